import gymnasium as gym
import pytest

from hnsdt.envs import LayoutError, load_layout, parse_layout


@pytest.mark.parametrize("text,match", [
    ("@.G\n..", "not rectangular"),
    ("@@G", "more than one start"),
    ("..G", "no start"),
    ("@..", "no goal"),
    ("@.GG", "more than one goal"),
    ("@A.G", "door 'A' has no key 'a'"),
    ("@a.?G", "unknown character '\\?'"),
    ("@a#G", "no path from the start reaches the goal"),
    ("@aA#bBG", "no path"),  # key b is behind door B: never reachable
    ("@.#1\n..##\na.AG", "item .1."),
    ("@aa.G", "appears more than once"),
    ("", "empty"),
])
def test_invalid_layouts_are_rejected_with_one_clear_line(text, match):
    with pytest.raises(LayoutError, match=match) as err:
        parse_layout(text)
    assert "\n" not in str(err.value)


def test_layout_sources(tmp_path):
    builtin = load_layout("keydoor_5x5")
    path = tmp_path / "mine.txt"
    path.write_text(builtin.text)
    assert load_layout(str(path)) == builtin
    assert load_layout(builtin.text) == builtin
    with pytest.raises(LayoutError, match="not a file"):
        load_layout("no_such_layout")


def test_a_bigger_layout_works_without_code_changes(tmp_path):
    text = "@.a.#....\n....A..b.\n#####B###\n.c..C..1.\n..2....3G\n"
    path = tmp_path / "three_keys.txt"
    path.write_text(text)
    env = gym.make("hnsdt/MultiKeyDoor-v0", layout=str(path))
    obs, _ = env.reset(seed=0)
    assert len(obs) == 2 + 3 + 3 + 3
    lay = env.unwrapped.layout
    assert lay.key_names == ["a", "b", "c"] and lay.door_names == ["A", "B", "C"]
    assert lay.item_names == ["1", "2", "3"]
