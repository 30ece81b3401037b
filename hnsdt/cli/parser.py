"""The ``hnsdt`` command line: its subcommands and their arguments, each bound to its function in
:mod:`.commands`."""

from __future__ import annotations

import argparse

from hnsdt.cli.commands import (cmd_collect, cmd_dataset_push, cmd_envs, cmd_evaluate, cmd_generalisation, cmd_pddl,
                                cmd_plan, cmd_replay, cmd_report, cmd_train)
from hnsdt.core.methods import LEARNED


def _drawn_arguments(p: argparse.ArgumentParser, action: str) -> None:
    p.add_argument("--drawn", help=f"{action}: a folder of layout files (*.txt, and those of its folders: maps of "
                   "any shape with the family's keys and doors), the split `drawn` in place of generalisation.drawn's "
                   "folder")
    p.add_argument("--drawn-max-steps", type=int, help=f"{action}: the episode step limit on the --drawn maps "
                   "(default: the experiment's own, generalisation.drawn.max_steps; 250 where it has none)")


def _run_arguments(p: argparse.ArgumentParser, func) -> None:
    """The tail of every command that runs tasks: --quiet, where they run, and what runs them."""
    from hnsdt.core.compute import EXECUTORS

    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--executor", choices=EXECUTORS, help="where the runs execute (default: compute.executor); "
                   "ray connects to RAY_ADDRESS or starts a local instance. The outputs do not depend on it")
    p.add_argument("--workers", type=int, help="local executor: runs at once (default: compute.workers; 0 = "
                   "one per core)")
    p.set_defaults(func=func)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hnsdt", description="Hierarchical Neuro-Symbolic Decision Transformer: environments, symbolic "
        "planner, datasets, training, evaluation, report and episode replay. The full pipeline runs with "
        "`dvc repro`; these commands run its parts.")
    parser.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("envs", help="list registered environments and built-in layouts")
    p.set_defaults(func=cmd_envs)

    p = sub.add_parser("plan", help="print the symbolic plan and its sub-goals for an environment")
    p.add_argument("--env", required=True, help="env name from params.yaml (keydoor), a gymnasium id, or a "
                   "MiniGrid id (its own world, stepped by MiniGrid)")
    p.add_argument("--layout", help="override the layout: built-in name, file path or grid text")
    p.add_argument("--mode", choices=["bfs", "cost"], default="bfs",
                   help="bfs: fewest operators (the paper's planner); cost: fewest steps (default: bfs)")
    p.add_argument("--operators", choices=["goto", "move"], default="goto",
                   help="goto: GoTo macro-operators (ours); move: the paper's one-cell Move operators "
                   "(default: goto)")
    p.add_argument("--state", help="plan from this observation, e.g. 4,0,1,0 (row,col,flags...)")
    p.add_argument("--seed", type=int, default=0, help="a MiniGrid id (MiniGrid-DoorKey-8x8-v0): the world its "
                   "reset with this seed makes (default: 0)")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("pddl", help="export the environment's domain and problem as PDDL")
    p.add_argument("--env", required=True, help="env name from params.yaml or a gymnasium id")
    p.add_argument("--layout", help="override the layout")
    p.add_argument("--out", required=True, help="output folder for domain.pddl and problem.pddl")
    p.add_argument("--operators", choices=["goto", "move"], default="goto",
                   help="goto: GoTo macro-operators (ours); move: the paper's one-cell Move operators")
    p.add_argument("--seed", type=int, default=0, help="a MiniGrid id: the world its reset with this seed makes")
    p.set_defaults(func=cmd_pddl)

    p = sub.add_parser("collect", help="collect exploration data into a LeRobot dataset (the `collect` stage)")
    p.add_argument("--env", required=True, help="env name from params.yaml (e.g. keydoor)")
    p.add_argument("--out", help="dataset folder (default: data/datasets/ENV)")
    p.add_argument("--repo-id", help="LeRobot repo id recorded in the dataset (default: local/ENV)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_collect)

    p = sub.add_parser("train", help="train one learned method on one env, every seed (the `train`, "
                       "`train_offline` and `train_online` stages)")
    p.add_argument("--env", required=True, help="env name from train.envs")
    p.add_argument("--method", required=True, choices=LEARNED, help="a learned method of the registry "
                   "(hnsdt.core.methods)")
    p.add_argument("--seed", type=int, nargs="+", help="training seeds (default: train.seeds of params.yaml)")
    p.add_argument("--dataset", help="offline methods: LeRobot dataset folder (default: data/datasets/ENV)")
    p.add_argument("--out", help="checkpoints folder, one seedK/ per seed (default: models/ENV/METHOD)")
    p.add_argument("--curves", help="training-curve folder, one seedK.csv per seed (default: "
                   "plots/train/ENV-METHOD)")
    _run_arguments(p, cmd_train)

    p = sub.add_parser("dataset", help="share a collected dataset")
    dsub = p.add_subparsers(dest="dataset_command", required=True, metavar="ACTION")
    q = dsub.add_parser("push", help="upload a dataset to the Hugging Face Hub with LeRobot's push_to_hub")
    q.add_argument("env", help="env name; the dataset is data/datasets/ENV unless --root")
    q.add_argument("--repo-id", required=True, help="OWNER/NAME on the Hub")
    q.add_argument("--private", action="store_true", help="create the Hub repository private")
    q.add_argument("--root", help="dataset folder (default: data/datasets/ENV)")
    q.add_argument("--dry-run", action="store_true", help="list the files and the card that would be "
                   "uploaded; no network")
    q.set_defaults(func=cmd_dataset_push)

    p = sub.add_parser("evaluate", help="evaluate every method x env x fail_prob x seed (the `evaluate` stage)")
    p.add_argument("--models", default="models", help="checkpoint root (default: models)")
    p.add_argument("--datasets", default="data/datasets", help="root of the collected datasets, one folder per "
                   "env (default: data/datasets; read for the training segment counts of Theorem 2)")
    p.add_argument("--out", default="results", help="results folder (default: results)")
    p.add_argument("--recordings", help="episode recordings folder (default: recordings beside --out)")
    _run_arguments(p, cmd_evaluate)

    p = sub.add_parser("generalisation", help="the unseen-layout experiment: collect on generated layouts, "
                       "train a method on views, evaluate on training / held-out / MiniGrid / drawn layouts (the "
                       "`*_generalisation` stages)")
    p.add_argument("action", choices=["collect", "train", "evaluate"])
    p.add_argument("--out", help="collect: dataset folder; train: checkpoints folder (one seedK/ per seed); "
                   "evaluate: results folder")
    p.add_argument("--method", choices=LEARNED, help="train: the method")
    p.add_argument("--dataset", default="generalisation/dataset", help="train: the collected dataset")
    p.add_argument("--curves", help="train: training-curve folder")
    p.add_argument("--models", help="evaluate: checkpoint root, one folder per method (default: the pipeline's, "
                   "generalisation/models, or generalisation/experiments/NAME/models with --experiment)")
    _drawn_arguments(p, "evaluate")
    p.add_argument("--splits", nargs="+", metavar="SPLIT", help="evaluate: only these splits (train, heldout, "
                   "minigrid, minigrid_16x16, drawn, ... as the experiment names them; default: every one), e.g. "
                   "`--drawn FOLDER --splits drawn` for your maps alone")
    p.add_argument("--methods", nargs="+", metavar="METHOD", help="evaluate: only these learned methods (the "
                   "symbolic reference runs always; default: every one), e.g. --methods hnsdt pure_dt")
    p.add_argument("--experiment", help="a name of unseen_experiments in params.yaml: its changes to the "
                   "generalisation section apply")
    _run_arguments(p, cmd_generalisation)

    p = sub.add_parser("report", help="figures and report.md from the evaluation (the `report` stage)")
    p.add_argument("--results", default="results")
    p.add_argument("--generalisation", help="results of the unseen-layout experiment (e.g. generalisation/results); "
                   "without it the report has no such section")
    p.add_argument("--out", default="report")
    p.add_argument("--headline", help="also write the headline metrics (success per method and split, HNSDT's "
                   "steps / optimum) into this folder, one JSON file per split, e.g. metrics/headline")
    p.add_argument("--ablations", help="measured variants of the unseen-layout experiment (e.g. "
                   "benchmarks/results/generalisation.csv, written by benchmarks/generalisation.py --record): "
                   "the report's ablation table and scaling figure")
    p.add_argument("--experiments", help="the folder of the further unseen-layout experiments' outputs (e.g. "
                   "generalisation/experiments, one folder per name of unseen_experiments)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("replay", help="the recording of any evaluated episode, of either experiment (.rrd for "
                       "rerun, .mcap for Foxglove)")
    p.add_argument("episode_id", nargs="?", help="an evaluated episode's id, METHOD/LAYOUT/fpP/seedK/epI, from an "
                   "evaluation's episodes.csv: e.g. hnsdt/keydoor/fp0.1/seed0/ep0 (the paper protocol) or "
                   "hnsdt/spiral_9x9/fp0.1/seed0/ep3 (an unseen layout); or a pattern for several, e.g. "
                   "'*/keydoor/fp0.1/seed0/ep0' (every method's, to compare side by side)")
    p.add_argument("--experiment", help="where to look: paper, unseen or a name of unseen_experiments (default: "
                   "every experiment's results; needed where an id is in several)")
    p.add_argument("--results", help="an evaluation's results folder elsewhere (default: the pipeline's)")
    p.add_argument("--models", help="the checkpoints it was evaluated with (default: the pipeline's for its "
                   "experiment)")
    _drawn_arguments(p, "replay")
    p.add_argument("--dataset", help="instead, render an episode of this collected LeRobot dataset folder")
    p.add_argument("--episode", type=int, default=0, help="with --dataset: the episode index")
    p.add_argument("--out", help="with --dataset, or an episode that was not recorded: the .rrd to write (an .mcap "
                   "is written beside it; default: the episode's id as a file name, here)")
    p.add_argument("--open", action="store_true", help="start the rerun viewer on the recording")
    p.set_defaults(func=cmd_replay)
    return parser
