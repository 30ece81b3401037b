"""The frames of our LeRobot datasets, defined once.

Each :class:`Feature` is one per-frame column: its LeRobot dtype, the names of its elements (its shape is their
count), what it means and where a frame's value comes from. Everything else is derived from :data:`FEATURES`:
the features a dataset is created with (:func:`info_features`, what ``meta/info.json`` lists), the dtypes a
dataset must have to be read (:data:`REQUIRED_DTYPES`), the dataset card's table (:func:`card_rows`) and each
written frame (:func:`frame`).

``when`` says which datasets have a feature: ``always``; ``image`` with ``collect.render`` > 0 (the grid as
video); ``view`` on datasets over many generated layouts; ``task`` is LeRobot's own string column (stored as
``task_index`` and ``meta/tasks``), described on the card and given with every frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from hnsdt.envs.keydoor import GOAL_REWARD, STEP_REWARD
from hnsdt.symbolic.subgoals import ID_TO_NAME

WHEN = ("always", "image", "view", "task")
NUMPY = {"int64": np.int64, "float32": np.float32, "bool": bool}


@dataclass(frozen=True)
class Feature:
    name: str
    dtype: str  # LeRobot's: int64, float32, bool, video (string: the task)
    meaning: str  # the card's words
    value: Callable[[dict, int], Any]  # (episode, step) -> the frame's value; the episode dicts of hnsdt.data.collect
    names: tuple[str, ...] = ()  # one per element; () = the dataset's (the layout's state, the view, the image)
    when: str = "always"

    def __post_init__(self):
        if self.when not in WHEN:
            raise ValueError(f"feature {self.name}: when must be one of {WHEN}, got {self.when!r}")


def _last(ep: dict, t: int) -> bool:
    return t == len(ep["actions"]) - 1


FEATURES = (
    Feature("observation.state", "int64",
            "row, column, then one 0/1 flag per key held, door open, item held (names in info.json)",
            lambda ep, t: ep["states"][t]),
    Feature("action", "int64", "0 up, 1 right, 2 down, 3 left, 4 pick / open",
            lambda ep, t: ep["actions"][t], ("action",)),
    Feature("next.reward", "float32", f"reward of this step: {STEP_REWARD:g} per step, {GOAL_REWARD:+g} more on the "
            "step that reaches the exit holding every item", lambda ep, t: ep["rewards"][t], ("reward",)),
    Feature("next.done", "bool", "the episode ended with this step (success or time limit)", _last, ("done",)),
    Feature("next.success", "bool", "this step reached the exit holding every item",
            lambda ep, t: _last(ep, t) and ep["success"], ("success",)),
    Feature("subgoal", "int64", "ψ id of the operator the frame serves: the planner's GoTo / Pick / Open operators, "
            "or hindsight labels of the same for random walks (0 = none)", lambda ep, t: ep["subgoal_ids"][t],
            ("subgoal_id",)),
    Feature("subgoal.target", "int64", "that operator's target cell (-1, -1 for none)",
            lambda ep, t: ep["subgoal_targets"][t], ("row", "col")),
    Feature("move_subgoal", "int64", "the paper's labelling (Appendix B), in hindsight: Move / PickKey / OpenDoor / "
            "PickItem", lambda ep, t: ep["move_subgoal_ids"][t], ("subgoal_id",)),
    Feature("move_subgoal.target", "int64", "that operator's target cell (a Move's destination)",
            lambda ep, t: ep["move_subgoal_targets"][t], ("row", "col")),
    Feature("task", "string", "the `subgoal`'s name, e.g. `GoTo(key a)`",
            lambda ep, t: ID_TO_NAME[int(ep["subgoal_ids"][t])], when="task"),
    Feature("observation.image", "video", "the grid drawn at this step (walls, keys, doors open or closed, items, "
            "exit, the agent as a disc), as video; only with `collect.render` > 0",
            lambda ep, t: ep["images"][t], when="image"),
    Feature("observation.view", "int64", "the (2r+1)×(2r+1) cells around the agent, row-major, as codes: 0 outside "
            "the map, 1 wall, 2 floor, 3 exit, 5+k key k (a = 0), 15+k closed door, 25+k open door, 35+k item k "
            "(`hnsdt.envs.observation`); the centre shows what lies under the agent, a key or item the agent holds "
            "is no longer drawn", lambda ep, t: ep["views"][t], when="view"),
    Feature("observation.map", "int64", "the whole grid in this state, row-major, as the view's codes, at the top "
            "left of a square of `map_side` (meta/hnsdt.json: the largest layout's larger dimension), the rest 0 "
            "(outside the map); the agent's row and column are its cell in it, and it is not drawn",
            lambda ep, t: ep["maps"][t], when="view"),
    Feature("layout_index", "int64", "which of the dataset's layouts the episode was played on (`layout_texts` in "
            "meta/hnsdt.json)", lambda ep, t: ep["layout_index"], ("layout",), when="view"),
)
REQUIRED_DTYPES = {f.name: f.dtype for f in FEATURES if f.when == "always"}  # what every dataset must have


def _has(f: Feature, image: bool, view: bool) -> bool:
    return f.when in ("always", "task") or (f.when == "image" and image) or (f.when == "view" and view)


def info_features(state_names: list[str], image_shape: tuple[int, int, int] | None = None,
                  view_radius: int = 0, map_side: int = 0) -> dict:
    """The features a dataset is created with (``LeRobotDataset.create``): ``image_shape`` (rows, cols, 3) when
    frames are drawn, ``view_radius`` > 0 and ``map_side`` (the whole map's square) on datasets over many
    layouts. The image comes first (the order of every dataset written so far)."""
    r = view_radius
    if r > 0 and map_side < 1:
        raise ValueError("a dataset over many layouts stores the whole map: map_side must be > 0")
    dataset_names = {"observation.state": tuple(state_names), "observation.image": ("height", "width", "channels"),
                     "observation.view": tuple(f"cell{dr:+d}{dc:+d}" for dr in range(-r, r + 1)
                                               for dc in range(-r, r + 1)),
                     "observation.map": tuple(f"r{i}c{j}" for i in range(map_side) for j in range(map_side))}
    chosen = [f for f in FEATURES if f.when != "task" and _has(f, image_shape is not None, r > 0)]
    out = {}
    for f in sorted(chosen, key=lambda f: f.when != "image"):  # stable: the image first, the rest in order
        names = f.names or dataset_names[f.name]
        shape = tuple(image_shape) if f.dtype == "video" else (len(names),)
        out[f.name] = {"dtype": f.dtype, "shape": shape, "names": list(names)}
    return out


def card_rows(image: bool, view: bool) -> list[tuple[str, str]]:
    """``(feature, meaning)`` of the card's table: the features this dataset has, ``task`` included."""
    return [(f.name, f.meaning) for f in FEATURES if _has(f, image, view)]


def frame(ep: dict, t: int, features: dict) -> dict:
    """Step ``t`` of episode ``ep`` as a LeRobot frame of ``features`` (:func:`info_features`), plus its task.
    An episode of a drawn dataset carries ``images``, one over many layouts ``views``, ``maps`` and
    ``layout_index``."""
    out = {}
    for f in FEATURES:
        if f.name == "task":
            out[f.name] = f.value(ep, t)
        elif f.name in features:
            value = f.value(ep, t)
            out[f.name] = value if f.dtype == "video" else np.asarray(value, dtype=NUMPY[f.dtype]).reshape(-1)
    return out
