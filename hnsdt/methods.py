"""The methods of the comparison, in one table: name, label, paradigm, how each learns, which arm.

The paper's seven (Section 5) in our configuration (arm ``ours``: GoTo macro-operators with a cost-optimal
planner, DTs trained on the noisy planner's segments, a return-conditioned pure DT), plus the paper's own
configuration of its two transformers (arm ``paper``, Appendices B and C): HNSDT with one-cell ``Move``
operators and BFS, trained only on random exploration labelled in hindsight, and the unconditioned pure DT.

Config validation, training, evaluation and the report all read this table, so a method's name means the same
thing everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    paradigm: str  # the architectural paradigm of the paper's grouped figure
    training: str  # "dataset" (offline, reads the LeRobot dataset), "online" (env interaction) or "none"
    stage: str  # the DVC stage that trains it ("" when it needs no training)
    condition: str = ""  # decision transformers: what conditions the model (hnsdt.models.dt.CONDITIONS)
    arm: str = "ours"  # "ours" or "paper": which planner settings (params `planner` / `planner.paper`) it uses


PARADIGMS = ("RNN", "traditional RL", "pure transformer", "symbolic", "neuro-symbolic")

METHODS = {m.name: m for m in (
    Method("lstm_hier", "LSTM hierarchical", "RNN", "dataset", "train_offline"),
    Method("gru", "GRU sequential", "RNN", "dataset", "train_offline"),
    Method("dqn", "DQN", "traditional RL", "online", "train_online"),
    Method("options", "Options (option-critic)", "traditional RL", "online", "train_online"),
    Method("pure_dt", "Pure DT", "pure transformer", "dataset", "train", "return"),
    Method("symbolic", "BFS + controllers", "symbolic", "none", ""),
    Method("hnsdt", "HNSDT (ours)", "neuro-symbolic", "dataset", "train", "subgoal"),
    Method("pure_dt_paper", "Pure DT (paper)", "pure transformer", "dataset", "train", "none", "paper"),
    Method("hnsdt_paper", "HNSDT (paper: Move + BFS)", "neuro-symbolic", "dataset", "train", "subgoal", "paper"),
)}

ARMS = ("ours", "paper")
PAPER_ARM = {"hnsdt": "hnsdt_paper", "pure_dt": "pure_dt_paper"}  # each of our transformers -> the paper's build
DT_METHODS = tuple(m.name for m in METHODS.values() if m.condition)  # decision transformers (stage `train`)
DT_CONDITION = {m.name: m.condition for m in METHODS.values() if m.condition}  # (hnsdt.models.dt)
OFFLINE_BASELINES = ("lstm_hier", "gru")  # recurrent behaviour cloning (stage `train_offline`)
ONLINE_BASELINES = ("dqn", "options")  # reinforcement learning on the environment (stage `train_online`)
LEARNED = DT_METHODS + OFFLINE_BASELINES + ONLINE_BASELINES


def method(name: str) -> Method:
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; expected one of {', '.join(METHODS)}")
    return METHODS[name]
