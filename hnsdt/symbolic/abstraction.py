"""The abstraction φ: a low-level state → the set of predicates that hold in it.

Predicates are plain strings: ``At(r,c)``, ``HasKey(a)``, ``DoorOpen(A)``, ``HasItem(1)`` and ``Done`` (at the
exit holding every item). :class:`SymbolicState` is the same information in a form the planner can search.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hnsdt.envs.layout import Cell, Layout
from hnsdt.envs.render import split_state


def at(cell: Cell) -> str:
    return f"At({cell[0]},{cell[1]})"


def has_key(k: str) -> str:
    return f"HasKey({k})"


def door_open(d: str) -> str:
    return f"DoorOpen({d})"


def has_item(i: str) -> str:
    return f"HasItem({i})"


DONE = "Done"


@dataclass(frozen=True, order=True)
class SymbolicState:
    cell: Cell
    keys: frozenset[str] = frozenset()
    doors: frozenset[str] = frozenset()
    items: frozenset[str] = frozenset()

    @classmethod
    def from_observation(cls, layout: Layout, obs: np.ndarray) -> "SymbolicState":
        obs = np.asarray(obs)  # (cached by the observation's bytes: executors read every step of every episode)
        return _from_observation(layout, obs.dtype.str, obs.shape, obs.tobytes())

    @classmethod
    def initial(cls, layout: Layout) -> "SymbolicState":
        return cls(layout.start)

    def to_observation(self, layout: Layout) -> np.ndarray:
        flags = (
            [k in self.keys for k in layout.keys]
            + [d in self.doors for d in layout.doors]
            + [i in self.items for i in layout.items]
        )
        return np.array([*self.cell, *flags], dtype=np.int64)

    def done(self, layout: Layout) -> bool:
        return self.cell == layout.goal and self.items >= set(layout.items)

    def predicates(self, layout: Layout) -> frozenset[str]:
        return _predicates(self, layout)


@lru_cache(maxsize=65536)
def _from_observation(layout: Layout, dtype: str, shape: tuple, data: bytes) -> SymbolicState:
    cell, keys, doors, items = split_state(layout, np.frombuffer(data, dtype=dtype).reshape(shape))
    return SymbolicState(cell, frozenset(keys), frozenset(doors), frozenset(items))


@lru_cache(maxsize=65536)
def _predicates(state: SymbolicState, layout: Layout) -> frozenset[str]:
    preds = {at(state.cell)}
    preds |= {has_key(k) for k in state.keys}
    preds |= {door_open(d) for d in state.doors}
    preds |= {has_item(i) for i in state.items}
    if state.done(layout):
        preds.add(DONE)
    return frozenset(preds)


def phi(layout: Layout, obs: np.ndarray) -> frozenset[str]:
    """φ(s): the predicates true in observation ``obs``."""
    return SymbolicState.from_observation(layout, obs).predicates(layout)
