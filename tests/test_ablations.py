"""The measured variants of the unseen-layout experiment (hnsdt.evaluation.ablations): recorded rows, the report's
ablation table and scaling figure."""

import pandas as pd
import pytest

from hnsdt.evaluation import ablations


def _variant(name, ingredient, maps=40, encoder="5×5 flattened", relabel=0, success=0.5, ratio=1.5,
             methods=("hnsdt", "pure_dt", "symbolic"), family="keydoor_maze"):
    rows = [dict(variant=name, ingredient=ingredient, family=family, train_layouts=maps, episodes_per_map=32,
                 encoder=encoder, relabel_rounds=relabel, seeds="0 1", method=m, split=s, success=success,
                 success_std=0.1, steps_ratio=ratio, validation_steps=30.0 if m != "symbolic" else float("nan"),
                 command="python benchmarks/generalisation.py", revision="abc", params_digest="p",
                 dataset_digest="d", cpu="cpu", seconds=1)
            for m in methods for s in ("train", "heldout", "minigrid", "drawn")]
    return pd.DataFrame(rows)


def test_a_method_measured_again_replaces_its_rows_of_that_variant_in_place(tmp_path):
    path = tmp_path / "variants.csv"
    for name, ingredient in (("default", "reference"), ("400 maps", "maps"), ("conv", "encoder")):
        ablations.record(path, _variant(name, ingredient, methods=("hnsdt", "symbolic")))
    ablations.record(path, _variant("400 maps", "maps", maps=400, success=0.9, methods=("hnsdt", "pure_dt")))
    rows = ablations.read(path)
    assert list(dict.fromkeys(rows.variant)) == ["default", "400 maps", "conv"]
    again = rows[rows.variant == "400 maps"]
    assert len(rows) == 3 * 8 + 4 and len(again) == 12  # pure DT joined, HNSDT replaced, the planner kept
    assert set(again[again.method != "symbolic"].success) == {0.9} and set(again[again.method == "symbolic"].success) == {0.5}
    assert [p.name for p in tmp_path.iterdir()] == ["variants.csv"]  # no temporaries left


def test_bad_variant_files_and_rows_give_one_clear_error(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("variant,method\nx,hnsdt\n")
    with pytest.raises(ValueError, match="not a table of measured variants"):
        ablations.read(bad)
    with pytest.raises(ValueError, match="unknown ingredient 'fonts'"):
        ablations.record(tmp_path / "v.csv", _variant("x", "fonts"))
    assert not (tmp_path / "v.csv").exists()


def test_the_scaling_figure_takes_the_variants_that_change_only_the_maps(tmp_path):
    rows = pd.concat([_variant("default", "reference"), _variant("400 maps", "maps", maps=400),
                      _variant("400 maps, conv", "encoder", maps=400, encoder="5×5 + 2 conv"),
                      _variant("DAgger", "relabelling", relabel=1)])
    assert sorted(set(ablations.scaling_points(rows).variant)) == ["400 maps", "default"]
    assert ablations.scaling_figure(rows, tmp_path / "scaling.png") and (tmp_path / "scaling.png").stat().st_size
    only_default = rows[rows.variant != "400 maps"]
    assert not ablations.scaling_figure(only_default, tmp_path / "none.png")  # one map count: no curve
    assert not (tmp_path / "none.png").exists()


def test_the_scaling_figure_follows_each_family_from_its_own_first_row(tmp_path):
    case2 = [_variant("multikeydoor", "family", family="multikeydoor"),
             _variant("multikeydoor, 400 maps", "maps", maps=400, family="multikeydoor"),
             _variant("multikeydoor, conv", "encoder", encoder="5×5 + 2 conv", family="multikeydoor")]
    rows = pd.concat([_variant("default", "reference"), *case2])
    points = ablations.scaling_points(rows)
    assert sorted(set(points.variant)) == ["multikeydoor", "multikeydoor, 400 maps"]  # (one count: no line)
    assert set(points[points.variant == "multikeydoor, 400 maps"].family) == {"multikeydoor"}
    orphan = _variant("obstacles, 400 maps", "maps", maps=400, family="keydoor_obstacles")  # no 40-map row of its own
    assert "obstacles, 400 maps" not in set(ablations.scaling_points(pd.concat([rows, orphan])).variant)
    assert ablations.scaling_figure(rows, tmp_path / "scaling.png")  # two map counts in one family: a curve
    one_count = rows[rows.variant != "multikeydoor, 400 maps"]  # two families, one map count each: none
    assert not ablations.scaling_figure(one_count, tmp_path / "none.png") and not (tmp_path / "none.png").exists()
    module = "5×5 flattened + whole-map planner"  # a family first measured with another encoder, then again ...
    mazes = [_variant("module, mazes", "family", encoder=module, family="keydoor_mazes"),
             _variant("module, walls block", "encoder", encoder=module, family="keydoor_mazes"),
             _variant("module, mazes, 9 × 9", "encoder", encoder="9×9 + module", family="keydoor_mazes"),
             _variant("module, walls block, 400 maps", "maps", maps=400, encoder=module, family="keydoor_mazes")]
    points = ablations.scaling_points(pd.concat([rows, *mazes]))  # ... its line starts from the latest measurement
    assert sorted(set(points[points.family == "keydoor_mazes"].variant)) == [
        "module, walls block", "module, walls block, 400 maps"]
    assert sorted(set(points[points.family != "keydoor_mazes"].variant)) == ["multikeydoor", "multikeydoor, 400 maps"]
    no_reference = pd.concat(case2)  # a file of variants without the reference row: no figure, no error
    assert not ablations.scaling_figure(no_reference, tmp_path / "none.png") and not (tmp_path / "none.png").exists()


def test_the_ablation_table_shows_each_learned_method_of_each_variant(tmp_path):
    path = tmp_path / "variants.csv"
    ablations.record(path, _variant("default", "reference", success=0.775, ratio=1.62))
    ablations.record(path, _variant("DAgger", "relabelling", relabel=1, methods=("pure_dt",)))
    ablations.record(path, _variant("DAgger", "relabelling", relabel=1, methods=("hnsdt",)))
    context = ablations.ablation_context(path, tmp_path / "scaling.png")
    lines = context["ablations"].splitlines()
    assert len(lines) == 2 + 4  # header, rule; each variant's HNSDT, then its pure DT (no planner rows)
    assert lines[2].startswith("| default | reference | 40 × 32 `keydoor_maze` | 5×5 flattened | 0 1 | HNSDT")
    assert "| 0.775 (1.62×) |" in lines[2] and lines[2].endswith("| `abc` |")
    assert "1 relabelled round(s)" in lines[4] and "| HNSDT" in lines[4] and "| Pure DT" in lines[5]
    assert context["ablations_scaling"] is False and context["ablations_revisions"] == ["abc"]
    assert ablations.ablation_context(tmp_path / "missing.csv", tmp_path / "s.png") == {"ablations": ""}
