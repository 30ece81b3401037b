import math
from pathlib import Path

import pandas as pd
import pytest

from conftest import REPO
from hnsdt.evaluation.tables import LAYOUT_CELL, metrics_json, per_seed_metrics, summary


def _table():
    rows = []
    # seed 0: 3 episodes, 2 successes (steps 10, 20), rewards 0.0, -1.0, -2.5
    for success, steps, reward in [(True, 10, 0.0), (True, 20, -1.0), (False, 25, -2.5)]:
        rows.append({"method": "m", "env": "e", "fail_prob": 0.1, "seed": 0, "success": success, "steps": steps,
                     "reward": reward})
    # seed 1: 2 episodes, 1 success (steps 12), rewards 0.2, -2.5
    for success, steps, reward in [(True, 12, 0.2), (False, 25, -2.5)]:
        rows.append({"method": "m", "env": "e", "fail_prob": 0.1, "seed": 1, "success": success, "steps": steps,
                     "reward": reward})
    return pd.DataFrame(rows)


def test_per_seed_metrics_use_successful_episodes_for_steps():
    per = per_seed_metrics(_table()).set_index("seed")
    assert per.loc[0, "success"] == pytest.approx(2 / 3)
    assert per.loc[0, "steps"] == pytest.approx(15.0)
    assert per.loc[0, "reward"] == pytest.approx(-3.5 / 3)
    assert per.loc[1, "success"] == pytest.approx(0.5) and per.loc[1, "steps"] == pytest.approx(12.0)


def test_summary_is_mean_and_std_over_seeds():
    row = summary(_table()).iloc[0]
    assert row.success_mean == pytest.approx((2 / 3 + 0.5) / 2)
    assert row.success_std == pytest.approx(pd.Series([2 / 3, 0.5]).std())
    assert row.steps_mean == pytest.approx(13.5) and row.seeds == 2
    nested = metrics_json(summary(_table()))
    assert nested["e"]["m"]["fail_0.1"]["success_mean"] == pytest.approx(round((2 / 3 + 0.5) / 2, 4))


def test_no_success_gives_missing_steps_not_zero():
    t = _table()
    t["success"] = False
    row = summary(t).iloc[0]
    assert row.success_mean == 0 and math.isnan(row.steps_mean)
    assert metrics_json(summary(t))["e"]["m"]["fail_0.1"]["steps_mean"] is None


def test_one_summary_serves_both_experiments():
    """The unseen layouts' episodes (a split of several maps, each episode with its exact optimum) go through the
    same summary as the paper's: the same success, steps and reward columns, plus steps / optimum over the
    successful episodes, the optimum's success and the number of maps; a std is 0 where fewer than two seeds
    have the metric, as on the paper's maps."""
    t = _table().rename(columns={"env": "split"})
    t["layout"] = ["a", "b", "a", "a", "b"]
    t["optimal_steps"] = [10.0, 10.0, 10.0, 6.0, 12.5]
    t["optimal_success"] = [1.0, 1.0, 0.5, 1.0, 1.0]
    paper = summary(_table()).iloc[0]
    row = summary(t, LAYOUT_CELL, sort=False).iloc[0]
    for column in ("success_mean", "success_std", "steps_mean", "reward_mean", "seeds"):
        assert row[column] == pytest.approx(paper[column])
    assert row.steps_ratio_mean == pytest.approx((1.5 + 2.0) / 2)  # seed 0: 10/10, 20/10; seed 1: 12/6
    assert row.optimal_success == pytest.approx((2.5 / 3 + 1.0) / 2) and row.layouts == 2
    assert "steps_ratio_mean" not in summary(_table())
    one_seed = summary(t[t.seed == 1], LAYOUT_CELL).iloc[0]
    assert one_seed.success_std == 0 and one_seed.steps_ratio_std == 0 and one_seed.seeds == 1


def test_seed_view_counts_solving_seeds_and_bootstraps_over_seeds():
    from hnsdt.report.claims import seed_view

    rows = [{"method": "dqn", "env": "e", "fail_prob": f, "seed": s, "success": s < 2, "steps": 30, "reward": 0.0}
            for s in range(5) for f in (0.0, 0.3) for _ in range(4)]  # 2 of 5 seeds always succeed, 3 never
    view = seed_view(pd.DataFrame(rows)).iloc[0]
    assert (view.seeds, view.solved) == (5, 2) and view.success == pytest.approx(0.4)
    assert 0.0 <= view.ci_low < 0.4 < view.ci_high <= 1.0
    assert seed_view(pd.DataFrame(rows)).equals(seed_view(pd.DataFrame(rows)))  # seeded resampling


def test_the_report_says_which_online_learners_never_reached_the_exit_in_training(tmp_path):
    """A row at 0.000 on the maps a learner trains on comes with its measured reason: the seeds that never ended a
    training episode at the exit are counted under the usage table, with the learner, the env and the budget."""
    from hnsdt.report.tables import usage_lines

    rows = [{"method": "ppo", "env": "multikeydoor", "seed": s, "training": "online", "env_steps": 150_528,
             "gradient_steps": 2352, "env_steps_kept": 10_240, "training_exits": exits}
            for s, exits in enumerate([0, 0, 3])]
    rows += [{"method": "dqn", "env": "multikeydoor", "seed": 0, "training": "online", "env_steps": 120_000,
              "gradient_steps": 29_500, "env_steps_kept": 120_000, "training_exits": 812},
             {"method": "gru", "env": "multikeydoor", "seed": 0, "training": "dataset", "dataset_frames": 9000,
              "epochs": 20.0, "gradient_steps": 300}]
    pd.DataFrame(rows).to_csv(tmp_path / "training_usage.csv", index=False)
    lines = usage_lines(tmp_path)
    assert "| multikeydoor | PPO | the environment | 150,528 | – | – | 2,352 | 10,240 | 1 |" in lines
    notes = [line for line in lines if line.startswith("- ")]
    assert notes == ["- PPO on multikeydoor: 2 of its 3 seeds never ended a training episode at the exit in up to "
                     "150,528 environment steps. With the step penalty its only reward until then, nothing it "
                     "learns points to the exit: this row measures its exploration, not what it would learn from a "
                     "success."]


def test_the_report_revision_is_dirty_for_code_changes_not_for_the_lock_file(tmp_path):
    import subprocess

    from hnsdt.core.provenance import git_revision

    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=tmp_path, check=True,
                       capture_output=True)

    (tmp_path / "sub").mkdir()
    for name in ("dvc.lock", "params.yaml", "sub/code.py"):
        (tmp_path / name).write_text("a\n")
    git("init", "-q")
    git("add", "-A")
    git("commit", "-qm", "x")
    rev = git_revision(tmp_path)
    assert len(rev) == 12
    (tmp_path / "dvc.lock").write_text("b\n")  # what `dvc repro` does while the report stage runs
    assert git_revision(tmp_path) == git_revision(tmp_path / "sub") == rev
    (tmp_path / "params.yaml").write_text("b\n")
    assert git_revision(tmp_path / "sub") == rev + "-dirty"


def test_the_headline_metrics_are_few_and_are_means_over_the_failure_probabilities():
    """`dvc metrics show` reads metrics/headline/ (a file per split): every method's success on each paper env
    and unseen split, HNSDT's steps / optimum, each the mean over fail_probs of the seed means; at most ~45 numbers with
    the default methods (the planners that learn nothing are left to the report)."""
    import json

    from hnsdt.report.headline import headline_metrics

    summ = pd.read_csv(Path(REPO) / "metrics/summary.csv")  # the committed run of the paper protocol
    unseen = pd.DataFrame([{"method": m, "split": split, "fail_prob": fp, "success_mean": 0.5 + fp,
                            "steps_ratio_mean": 1.0 + fp}
                           for m in ("hnsdt", "pure_dt", "lstm_hier", "gru", "dqn", "options", "symbolic")
                           for split in ("train", "heldout", "minigrid", "drawn") for fp in (0.0, 0.2)])
    head = headline_metrics(summ, unseen)
    numbers = [v for split in head.values() for v in split.values()]
    assert len(numbers) <= 45 and set(head) == {"keydoor", "multikeydoor", "heldout", "minigrid", "drawn"}
    cells = summ[(summ.env == "multikeydoor") & (summ.method == "hnsdt_paper")]
    assert head["multikeydoor"]["hnsdt_paper"] == round(cells.success_mean.mean(), 4)
    assert head["heldout"] == {m: 0.6 for m in ("hnsdt", "pure_dt", "lstm_hier", "gru", "dqn", "options")} | {
        "hnsdt_steps_ratio": 1.1}
    assert "symbolic" not in head["keydoor"] and "symbolic_paper" not in head["keydoor"]
    assert head["keydoor"]["hnsdt_steps_ratio"] == round(summ[(summ.env == "keydoor") & (summ.method == "hnsdt")]
                                                         .steps_ratio.mean(), 4)
    json.dumps(head, allow_nan=False)  # no NaN reaches the metrics file


def _episode_bytes(ep) -> tuple:
    return (ep.states.tobytes(), ep.actions.tobytes(), ep.rewards.tobytes(), ep.subgoal_ids.tobytes(),
            ep.subgoal_targets.tobytes(), ep.success, tuple(ep.plan), ep.replans)


@pytest.mark.parametrize("method", ["options", "hnsdt"])
def test_a_methods_cells_stepped_as_one_batch_are_the_cells_run_alone(keydoor, method):
    """The evaluation steps a method's fail_prob cells as one batch (cell_batches); each cell's episodes are those
    of a batch of its own: the env's draws and the agent's (an option-critic samples actions and terminations)
    come from the cell's own seed, and a transformer's cached decisions do not depend on what else is in the
    batch."""
    import torch

    from hnsdt.agents.executor import ExecutorConfig
    from hnsdt.evaluation.runs import Batch, EvalTask, run_batch
    from hnsdt.evaluation.paper import cell_batches, cell_outputs
    from hnsdt.models.dt import DecisionTransformer, DTConfig
    from hnsdt.models.qnetwork import OptionCritic, OptionCriticConfig

    torch.manual_seed(0)
    if method == "options":
        model = OptionCritic(OptionCriticConfig(keydoor.n_flags, *keydoor.shape, hidden=16)).eval()
    else:
        model = DecisionTransformer(DTConfig("subgoal", keydoor.n_flags, *keydoor.shape, context=3, n_layers=1,
                                             d_model=16, max_timestep=100, formulation="episode")).eval()
    (batch,) = cell_batches(method, "keydoor", 0, (0.0, 0.2, 0.3), keydoor, 30, 6)
    task = EvalTask(method, 0, ExecutorConfig(), model, {}, 0.1, (batch,), cell_outputs)
    assert batch.copies == 18 and len(set(batch.seed)) == 3
    together = run_batch(task, batch)
    alone = [ep for cell, seed in zip(batch.key, batch.seed)
             for ep in run_batch(task, Batch(keydoor, 30, 6, cell.fail_prob, seed, cell))]
    assert [_episode_bytes(e) for e in together] == [_episode_bytes(e) for e in alone]
    assert len({e.states.tobytes() for e in together}) > 3  # the draws matter: the episodes differ
    rows = cell_outputs(task, batch, together)
    assert [r[0][0]["episode_id"] for r in rows] == [f"{method}/keydoor/fp{fp:g}/seed0/ep0" for fp in (0, 0.2, 0.3)]


def test_the_learning_curves_come_from_the_checkpoints_with_the_kept_evaluation_marked(tmp_path):
    """The report's learning curves: every seed's recorded evaluations, the one it kept, whether it stopped
    before the cap; methods without a validation history named as trained to a fixed budget; an online learner
    whose seeds hardly ever reached the exit in training named with its counts. Each experiment's figure is
    written."""
    import json

    from hnsdt.report.curves import curve_lines, curves_figure, histories, read_usages, trained_methods, training_exits

    def checkpoint(method, seed, usage):
        folder = tmp_path / "models/keydoor" / method / f"seed{seed}"
        folder.mkdir(parents=True)
        (folder / "config.json").write_text(json.dumps({"usage": usage}))

    for seed in (0, 1):
        checkpoint("ppo", seed, {"env_steps": 30_000, "episodes": 300, "exits": seed, "stopped_early": seed == 0,
                                 "best_step": 10_000 * (1 + seed), "validation_floor": 14.0,
                                 "validation_steps": [{"step": 10_000, "value": 40.0},
                                                      {"step": 20_000, "value": 30.0 + 20 * (1 - seed)},
                                                      {"step": 30_000, "value": 35.0}]})
        checkpoint("hnsdt", seed, {"best_epoch": 2, "stopped_early": True,
                                   "validation_loss": [{"epoch": e, "step": 10 * e, "value": 1.0 / e} for e in (1, 2)]})
        checkpoint("gru", seed, {"epochs": 20.0})
    usages = read_usages({"keydoor": tmp_path / "models/keydoor"})
    h = histories(usages)
    kept = h[h.kept].sort_values(["method", "seed"])
    assert list(zip(kept.method, kept.seed, kept.x)) == [("hnsdt", 0, 2), ("hnsdt", 1, 2), ("ppo", 0, 10_000),
                                                         ("ppo", 1, 20_000)]
    assert set(h[h.method == "ppo"].unit) == {"environment steps"} and set(h[h.method == "hnsdt"].unit) == {"epochs"}
    lines = curve_lines(h, trained_methods(usages), training_exits(usages))
    assert lines[0].startswith("- keydoor: seeds stopped at their plateau before the cap: PPO 1 of 2, HNSDT (ours) 2")
    assert lines[0].endswith("(no curve): GRU sequential.")
    assert lines[1] == ("  - PPO: 0–1 of its 300 training episodes a seed ended at the exit in up to 30,000 "
                        "environment steps: too few successes to learn the way from within this cap.")
    curves_figure(h, "keydoor", tmp_path / "curves.png")
    assert (tmp_path / "curves.png").stat().st_size > 5_000
