"""The methods of the comparison, in one registry: every fact about a method lives in its entry here.

The paper's seven (Section 5) in our configuration (arm ``ours``: GoTo macro-operators with a cost-optimal
planner, DTs trained on the noisy planner's segments, a return-conditioned pure DT), plus the paper's own
configuration of its two transformers (arm ``paper``, Appendices B and C): HNSDT with one-cell ``Move``
operators and BFS, trained only on random exploration labelled in hindsight, and the unconditioned pure DT.

Config validation, the CLI, training, evaluation, checkpoints, the report and the tests all read this table;
no other module spells a method's name. An entry names the code that implements the method as
``"module:attribute"`` strings, imported only when used (so reading the table costs no torch import):

* ``network``: the model class (its ``arch`` names the checkpoint architecture, its ``config_class`` the
  network knobs), ``config``: the training-knob dataclass, both filled from ``params.yaml``;
* ``trainer``: ``trainer(data, network_cfg, train_cfg, progress, desc, network) -> (model, curve, usage)``,
  where ``data`` is the dataset's frames (``training="dataset"``) or ``(layout, max_steps)`` (``"online"``);
  each also takes ``stop_after`` (epochs, or env steps online) and ``state``: it then returns a state to
  continue from instead, which ``state`` resumes (:mod:`hnsdt.models.fit`, ``OnlineRun.pause``);
* ``agent``: ``agent(model, meta, layout, executor, epsilon, seed)``, the batched agent that is evaluated.

Adding a method: README, "Adding a method".
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    paradigm: str  # the architectural paradigm of the paper's grouped figure
    training: str  # "dataset" (offline, reads the LeRobot dataset), "online" (env interaction) or "none"
    stage: str  # the DVC stage group that trains it ("" when it needs no training)
    agent: str  # "module:function" building the evaluated agent (see the module docstring)
    network: str = ""  # "module:Class" of the trained model
    config: str = ""  # "module:Class" of its training knobs
    trainer: str = ""  # "module:function" that trains it
    fixed: dict[str, Any] = field(default_factory=dict)  # network knobs the method fixes (not in params.yaml)
    condition: str = ""  # decision transformers: what conditions the model (hnsdt.models.dt.CONDITIONS)
    arm: str = "ours"  # "ours" or "paper": which planner settings (params `planner` / `planner.paper`) it uses
    view_network: str = ""  # "module:Class" of the same model reading the grid around the agent (unseen layouts)


PARADIGMS = ("RNN", "traditional RL", "pure transformer", "symbolic", "neuro-symbolic")
ARMS = ("ours", "paper")

_DT = dict(training="dataset", stage="train", agent="hnsdt.agents.dt_agents:make_agent",
           network="hnsdt.models.dt:DecisionTransformer", config="hnsdt.models.train:TrainConfig",
           trainer="hnsdt.models.train:train_decision_transformer",
           view_network="hnsdt.models.view:ViewDecisionTransformer")
_RNN = dict(training="dataset", stage="train_offline", agent="hnsdt.baselines.recurrent:make_agent",
            network="hnsdt.models.recurrent:RecurrentPolicy",
            config="hnsdt.baselines.recurrent:RecurrentTrainConfig",
            trainer="hnsdt.baselines.recurrent:train_recurrent",
            view_network="hnsdt.models.view:ViewRecurrentPolicy")

METHODS = {m.name: m for m in (
    Method("lstm_hier", "LSTM hierarchical", "RNN", **_RNN, fixed={"cell": "lstm", "hierarchical": True}),
    Method("gru", "GRU sequential", "RNN", **_RNN, fixed={"cell": "gru", "hierarchical": False}),
    Method("dqn", "DQN", "traditional RL", "online", "train_online", "hnsdt.baselines.dqn:make_agent",
           "hnsdt.models.qnetwork:QNetwork", "hnsdt.baselines.dqn:DQNConfig",
           "hnsdt.baselines.dqn:train_dqn", view_network="hnsdt.models.view:ViewQNetwork"),
    Method("options", "Options (option-critic)", "traditional RL", "online", "train_online",
           "hnsdt.baselines.options:make_agent", "hnsdt.models.qnetwork:OptionCritic",
           "hnsdt.baselines.options:OptionsConfig", "hnsdt.baselines.options:train_options",
           view_network="hnsdt.models.view:ViewOptionCritic"),
    Method("pure_dt", "Pure DT", "pure transformer", **_DT, condition="return"),
    Method("symbolic", "BFS + controllers", "symbolic", "none", "", "hnsdt.agents.symbolic:make_agent"),
    Method("hnsdt", "HNSDT (ours)", "neuro-symbolic", **_DT, condition="subgoal"),
    Method("pure_dt_paper", "Pure DT (paper)", "pure transformer", **_DT, condition="none", arm="paper"),
    Method("hnsdt_paper", "HNSDT (paper: Move + BFS)", "neuro-symbolic", **_DT, condition="subgoal", arm="paper"),
    Method("symbolic_paper", "Move + BFS + one-cell controllers", "symbolic", "none", "",
           "hnsdt.agents.symbolic:make_agent", arm="paper"),
)}

PROPOSED = "hnsdt"  # the paper's method: the theorems' subject and the report's reference line
REFERENCE = "symbolic"  # needs no training: the unseen-layout experiment runs it on every split as the reference
PAPER_ARM = {"hnsdt": "hnsdt_paper", "pure_dt": "pure_dt_paper"}  # each of our transformers -> the paper's build
# Each plan-following DT -> the hand-written controllers under the same planner: the steps a perfect executor of
# those sub-goals would take (the report's decomposition of the paper's HNSDT's steps)
CONTROLLER_FLOOR = {"hnsdt": "symbolic", "hnsdt_paper": "symbolic_paper"}
DT_METHODS = tuple(m.name for m in METHODS.values() if m.stage == "train")  # configured under `train`
OFFLINE_BASELINES = tuple(m.name for m in METHODS.values() if m.stage == "train_offline")  # `baselines.offline`
ONLINE_BASELINES = tuple(m.name for m in METHODS.values() if m.stage == "train_online")  # `baselines.online`
BASELINES = OFFLINE_BASELINES + ONLINE_BASELINES  # configured under `baselines.<name>`
LEARNED = DT_METHODS + BASELINES
STAGES = {"train": DT_METHODS, "train_offline": OFFLINE_BASELINES, "train_online": ONLINE_BASELINES}


def method(name: str) -> Method:
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; expected one of {', '.join(METHODS)}")
    return METHODS[name]


def resolve(ref: str) -> Any:
    """The object a ``"module:attribute"`` reference of the registry names."""
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


def architectures() -> dict[str, str]:
    """Checkpoint architecture name -> model class reference, over every registered network."""
    out = {}
    for ref in dict.fromkeys(r for m in METHODS.values() for r in (m.network, m.view_network) if r):
        out[resolve(ref).arch] = ref
    return out


def network_for(name: str, cfg) -> type:
    """The class of ``name``'s network that ``cfg`` configures: its ``network`` or its ``view_network``."""
    entry = method(name)
    for ref in (entry.network, entry.view_network):
        if ref and resolve(ref).config_class is type(cfg):
            return resolve(ref)
    raise ValueError(f"{name}: no network of this method is configured by a {type(cfg).__name__}")
