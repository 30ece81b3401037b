"""The methods of the comparison, in one registry: every fact about a method lives in its entry here.

The paper's seven (Section 5) in our configuration (arm ``ours``: GoTo macro-operators with a cost-optimal
planner, DTs trained on the noisy planner's segments, a return-conditioned pure DT), plus the paper's own
configuration of its two transformers (arm ``paper``, Appendices B and C): HNSDT with one-cell ``Move``
operators and BFS, trained only on random exploration labelled in hindsight, and the unconditioned pure DT.

Config validation, the CLI, training, evaluation, checkpoints, the report and the tests all read this table;
no other module spells a method's name. It holds facts only and imports nothing of ours: an entry's ``code``
names the family of code that implements it, which :mod:`hnsdt.implementations` (a layer up, beside the agents
and baselines) maps to its network, training knobs, trainer and agent.

Adding a method: README, "Adding a method".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    paradigm: str  # the architectural paradigm of the paper's grouped figure
    training: str  # "dataset" (offline, reads the LeRobot dataset), "online" (env interaction) or "none"
    stage: str  # the DVC stage group that trains it ("" when it needs no training)
    code: str  # the family of code that implements it (hnsdt.implementations.CODE)
    fixed: dict[str, Any] = field(default_factory=dict)  # network knobs the method fixes (not in params.yaml)
    condition: str = ""  # decision transformers: what conditions the model (hnsdt.models.dt.CONDITIONS)
    arm: str = "ours"  # "ours" or "paper": which planner settings (params `planner` / `planner.paper`) it uses


PARADIGMS = ("RNN", "traditional RL", "pure transformer", "symbolic", "neuro-symbolic")
ARMS = ("ours", "paper")

_DT = dict(training="dataset", stage="train", code="transformer")
_RNN = dict(training="dataset", stage="train_offline", code="recurrent")

METHODS = {m.name: m for m in (
    Method("lstm_hier", "LSTM hierarchical", "RNN", **_RNN, fixed={"cell": "lstm", "hierarchical": True}),
    Method("gru", "GRU sequential", "RNN", **_RNN, fixed={"cell": "gru", "hierarchical": False}),
    Method("dqn", "DQN", "traditional RL", "online", "train_online", "q_learning"),
    Method("options", "Options (option-critic)", "traditional RL", "online", "train_online", "option_critic"),
    Method("ppo", "PPO", "traditional RL", "online", "train_online", "policy_gradient"),
    Method("pure_dt", "Pure DT", "pure transformer", **_DT, condition="return"),
    Method("symbolic", "BFS + controllers", "symbolic", "none", "", "controllers"),
    Method("hnsdt", "HNSDT (ours)", "neuro-symbolic", **_DT, condition="subgoal"),
    Method("pure_dt_paper", "Pure DT (paper)", "pure transformer", **_DT, condition="none", arm="paper"),
    Method("hnsdt_paper", "HNSDT (paper: Move + BFS)", "neuro-symbolic", **_DT, condition="subgoal", arm="paper"),
    Method("symbolic_paper", "Move + BFS + one-cell controllers", "symbolic", "none", "", "controllers",
           arm="paper"),
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
OUR_DTS = tuple(m.name for m in METHODS.values() if m.stage == "train" and m.arm == "ours")
# On MiniGrid's own worlds (hnsdt.compose.minigrid): our transformers, the RNN baselines and the online ones
MINIGRID_LEARNERS = OUR_DTS + OFFLINE_BASELINES + ONLINE_BASELINES
STAGES = {"train": DT_METHODS, "train_offline": OFFLINE_BASELINES, "train_online": ONLINE_BASELINES}


def method(name: str) -> Method:
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; expected one of {', '.join(METHODS)}")
    return METHODS[name]

