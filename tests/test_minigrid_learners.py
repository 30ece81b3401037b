"""MiniGrid learners measured outside the default run (hnsdt.evaluation.minigrid_learners): recorded from a
finished stage output, and set beside the default run's learners in the report, marked."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hnsdt.evaluation import minigrid_learners
from hnsdt.evaluation.minigrid import LEARNED_COLUMNS, SUMMARY_COLUMNS, to_csv

ENV = "MiniGrid-DoorKey-8x8-v0"
FAIL_PROBS = (0.0, 0.3)


def _learned(out: Path, methods: dict[str, float], revision: str = "abc123def456") -> Path:
    """A finished `minigrid_learn` output: per method its success, two seeds' curves (online: never a goal, to
    the cap) and checkpoints."""
    rows = [dict(env=ENV, fail_prob=p, method=m, seeds=2, worlds=20, success_mean=s, success_std=0.0,
                 reward_mean=0.9 * s, reward_std=0.0, steps_mean=20.0 if s else float("nan"),
                 steps_std=1.0 if s else float("nan"), gave_up=0) for m, s in methods.items() for p in FAIL_PROBS]
    (out / "curves").mkdir(parents=True)
    (out / "summary.csv").write_text(to_csv(rows, LEARNED_COLUMNS))
    (out / "provenance.json").write_text(json.dumps({"git_revision": revision, "params_digest": "0123456789abcdef"}))
    for m in methods:
        for seed in (0, 1):
            usage = {"frames": 250_000 + seed, "best_step": 50_000, "stopped_early": False,
                     "validation_steps": [{"step": 50_000, "value": 100.0}, {"step": 100_000, "value": 100.0}]}
            (out / "curves" / f"{m}-seed{seed}.json").write_text(json.dumps({"curve": [], "usage": usage}))
            (out / "models" / m / f"seed{seed}").mkdir(parents=True)
            (out / "models" / m / f"seed{seed}" / "config.json").write_text(json.dumps({"dataset_md5": "d" * 32}))
    return out


def test_a_finished_stages_rows_are_recorded_with_what_made_them_and_a_measured_again_method_replaces_its_own(
        tmp_path):
    out = _learned(tmp_path / "run", {"dqn": 0.0, "options": 0.25, "ppo": 0.5})
    rows = minigrid_learners.stage_rows(out, ["dqn", "options"], 100.0, command="python b.py", cpu="x", seconds=9)
    assert list(rows.columns) == minigrid_learners.COLUMNS and len(rows) == 4  # (2 methods x 2 fail_probs)
    dqn = rows[rows.method == "dqn"].iloc[0]
    assert (dqn.revision, dqn.params_digest, dqn.dataset_md5, dqn.command) == (
        "abc123def456", "0123456789abcdef", "d" * 32, "python b.py")
    assert dqn.data == "250,000–250,001 env steps" and dqn.best_validation == "100.0"
    assert dqn.stopped == "none: no measurement reached a goal, so each trained to its cap"
    path = tmp_path / "learners.csv"
    minigrid_learners.record(path, rows)
    again = _learned(tmp_path / "again", {"dqn": 0.75}, revision="fedcba987654")
    minigrid_learners.record(path, minigrid_learners.stage_rows(again, ["dqn"], 100.0, command="c", cpu="y",
                                                                seconds=1))
    kept = minigrid_learners.read(path)
    assert len(kept) == 4 and list(kept.method) == ["options", "options", "dqn", "dqn"]  # (replaced, not doubled)
    assert set(kept[kept.method == "dqn"].revision) == {"fedcba987654"} and set(kept.success_mean) == {0.25, 0.75}
    with pytest.raises(ValueError, match=r"no rows of gru$"):
        minigrid_learners.stage_rows(out, ["gru"], 100.0)
    with pytest.raises(FileNotFoundError, match=r"no finished minigrid_learn output"):
        minigrid_learners.stage_rows(tmp_path, ["dqn"], 100.0)
    (tmp_path / "bad.csv").write_text("env,method\nx,y\n")
    with pytest.raises(ValueError, match=r"bad.csv: not a table of MiniGrid learners \(missing columns: fail_prob"):
        minigrid_learners.read(tmp_path / "bad.csv")


def test_the_report_sets_the_recorded_learners_beside_the_default_runs_marked_and_only_for_its_worlds(tmp_path):
    from hnsdt.compose.config import load_params
    from hnsdt.report.minigrid import MEASURED_MARK, minigrid_context

    repo = Path(__file__).resolve().parent.parent
    params = load_params(repo / "params.yaml", ["minigrid.envs={doorkey8: {id: MiniGrid-DoorKey-8x8-v0}}",
                                                f"minigrid.fail_probs={list(FAIL_PROBS)}",
                                                "minigrid.learn.methods=[ppo]"])
    folder = tmp_path / "minigrid"
    reference = [dict(env=ENV, fail_prob=p, method=m, worlds=20, success_mean=1.0, reward_mean=0.9,
                      steps_mean=20.0, plans_mean=1.0, gave_up=0)
                 for p in FAIL_PROBS for m in ("optimum", "babyai_bot", "symbolic")]
    (folder / "doorkey8" / "reference").mkdir(parents=True)
    (folder / "doorkey8" / "reference" / "summary.csv").write_text(to_csv(reference, SUMMARY_COLUMNS))
    _learned(folder / "doorkey8" / "learned", {"ppo": 0.0})
    run = _learned(tmp_path / "run", {"dqn": 0.0, "options": 0.5, "ppo": 0.25})
    path = tmp_path / "learners.csv"
    rows = minigrid_learners.stage_rows(run, ["dqn", "options", "ppo"], 100.0, command="python b.py --world doorkey8",
                                        cpu="AMD EPYC", seconds=1045)
    other = rows.assign(env="MiniGrid-UnlockPickup-v0")  # (a world this params does not have)
    minigrid_learners.record(path, rows)
    minigrid_learners.record(path, other)
    plain = minigrid_context(params, folder)
    context = minigrid_context(params, folder, path)
    added = [line for line in context["minigrid_learned"] if line not in plain["minigrid_learned"]]
    assert [line.split(" | ")[1:3] for line in added] == [
        ["0", "DQN" + MEASURED_MARK], ["0", "Options (option-critic)" + MEASURED_MARK],
        ["0.3", "DQN" + MEASURED_MARK], ["0.3", "Options (option-critic)" + MEASURED_MARK]]  # (ppo: the default's)
    assert "| 0.500 ± 0.000 | 20.0 ± 1.0 (1.00×) |" in added[1] and "| 0.000 ± 0.000 | – |" in added[0]
    assert len(context["minigrid_learned"]) == 6 and all("UnlockPickup" not in line for line in added)
    budgets = [line for line in context["minigrid_budgets"] if MEASURED_MARK in line]
    assert budgets == [f"| {ENV} | DQN{MEASURED_MARK} | 250,000–250,001 env steps | none: no measurement reached a "
                       "goal, so each trained to its cap | 100.0 |",
                       f"| {ENV} | Options (option-critic){MEASURED_MARK} | 250,000–250,001 env steps | none: no "
                       "measurement reached a goal, so each trained to its cap | 100.0 |"]
    assert context["minigrid_measured"] == [f"{ENV}: DQN, Options (option-critic) — `python b.py --world doorkey8`, "
                                            "revision `abc123def456`, 1,045 s on AMD EPYC"]
    assert plain["minigrid_measured"] == [] and minigrid_context(params, folder, tmp_path / "none.csv")[
        "minigrid_learned"] == plain["minigrid_learned"]
    minigrid_learners.record(path, minigrid_learners.stage_rows(run, ["dqn"], 100.0, command="python c.py", cpu="x",
                                                                seconds=7))  # (one method measured again, apart)
    assert minigrid_context(params, folder, path)["minigrid_measured"] == [
        f"{ENV}: Options (option-critic) — `python b.py --world doorkey8`, revision `abc123def456`, 1,045 s on "
        "AMD EPYC",
        f"{ENV}: DQN — `python c.py`, revision `abc123def456`, 7 s on x"]
    minigrid_learners.record(path, minigrid_learners.stage_rows(run, ["dqn"], 100.0, command="python c.py", cpu="x",
                                                                seconds=float("nan")))  # (recorded, its time unknown)
    assert minigrid_context(params, folder, path)["minigrid_measured"][1:] == [
        f"{ENV}: DQN — `python c.py`, revision `abc123def456`, on x"]  # (one line for its rows, no "nan s")
