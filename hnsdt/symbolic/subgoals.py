"""ψ: operator → sub-goal token, an integer id in a fixed, layout-independent vocabulary plus a target cell.

The vocabulary enumerates every operator any layout can ground (26 keys, 26 doors, 10 items, the exit, and one
id for all of the paper's ``Move`` operators: ψ(Move(c → c')) is that id with target c', the paper's "Move to
cell (r',c')"), so a model trained on one layout reads the same ids on another. Id 0, ``none``, marks frames that serve no
sub-goal (the tail of an exploration episode after its last achieved effect).
"""

from __future__ import annotations

import string
from dataclasses import dataclass
from functools import lru_cache

from hnsdt.envs.layout import Cell
from hnsdt.symbolic.operators import (
    GOTO_DOOR, GOTO_EXIT, GOTO_ITEM, GOTO_KEY, MOVE, OPEN_DOOR, PICK_ITEM, PICK_KEY, Operator,
)

NONE_ID = 0
NONE_NAME = "none"
_SYMBOLS = {
    GOTO_KEY: string.ascii_lowercase, PICK_KEY: string.ascii_lowercase,
    GOTO_DOOR: string.ascii_uppercase, OPEN_DOOR: string.ascii_uppercase,
    GOTO_ITEM: string.digits, PICK_ITEM: string.digits, GOTO_EXIT: ("exit",), MOVE: ("",),
}
_BASE: dict[str, int] = {}
_next = 1
for _kind, _symbols in _SYMBOLS.items():
    _BASE[_kind] = _next
    _next += len(_symbols)
VOCAB_SIZE = _next
_NAME_FORMAT = {
    GOTO_KEY: "GoTo(key {})", PICK_KEY: "PickKey({})", GOTO_DOOR: "GoTo(door {})", OPEN_DOOR: "OpenDoor({})",
    GOTO_ITEM: "GoTo(item {})", PICK_ITEM: "PickItem({})", GOTO_EXIT: "GoTo(exit)", MOVE: "Move{}",
}
ID_TO_NAME = [NONE_NAME] + [_NAME_FORMAT[k].format(sym) for k, syms in _SYMBOLS.items() for sym in syms]
NAME_TO_ID = {name: i for i, name in enumerate(ID_TO_NAME)}


@dataclass(frozen=True)
class SubGoal:
    id: int
    target: Cell

    @property
    def name(self) -> str:
        return ID_TO_NAME[self.id]


NO_SUBGOAL = SubGoal(NONE_ID, (-1, -1))


def subgoal_id(op: Operator) -> int:
    return _BASE[op.kind] + (0 if op.kind == MOVE else _SYMBOLS[op.kind].index(op.obj))


@lru_cache(maxsize=65536)  # (every executor asks for its operator's token at every step)
def psi(op: Operator) -> SubGoal:
    """ψ(o): the sub-goal token that conditions the decision transformer while ``op`` executes."""
    return SubGoal(subgoal_id(op), op.target)
