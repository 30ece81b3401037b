"""The seven methods of the paper's comparison (Section 5), in one table: name, label, paradigm, how each learns.

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


PARADIGMS = ("RNN", "traditional RL", "pure transformer", "symbolic", "neuro-symbolic")

METHODS = {m.name: m for m in (
    Method("lstm_hier", "LSTM hierarchical", "RNN", "dataset", "train_offline"),
    Method("gru", "GRU sequential", "RNN", "dataset", "train_offline"),
    Method("dqn", "DQN", "traditional RL", "online", "train_online"),
    Method("options", "Options (option-critic)", "traditional RL", "online", "train_online"),
    Method("pure_dt", "Pure DT", "pure transformer", "dataset", "train"),
    Method("symbolic", "BFS + controllers", "symbolic", "none", ""),
    Method("hnsdt", "HNSDT (ours)", "neuro-symbolic", "dataset", "train"),
)}

DT_METHODS = ("hnsdt", "pure_dt")  # decision transformers (stage `train`)
DT_CONDITION = {"hnsdt": "subgoal", "pure_dt": "return"}  # what conditions each one (hnsdt.models.dt)
OFFLINE_BASELINES = ("lstm_hier", "gru")  # recurrent behaviour cloning (stage `train_offline`)
ONLINE_BASELINES = ("dqn", "options")  # reinforcement learning on the environment (stage `train_online`)
LEARNED = DT_METHODS + OFFLINE_BASELINES + ONLINE_BASELINES


def method(name: str) -> Method:
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; expected one of {', '.join(METHODS)}")
    return METHODS[name]
