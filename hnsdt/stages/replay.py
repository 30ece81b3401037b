"""Any evaluated episode of either experiment, found by its id (``METHOD/LAYOUT/fpP/seedK/epI``,
:func:`hnsdt.evaluation.runs.episode_id`) and recorded (``hnsdt replay``): the recording the evaluation kept, or
the episode made again from its checkpoint and seeds, checked against its row of the evaluation. Not a DVC stage.

The experiments are the paper protocol (``paper``: ``results/``, ``models/``), the unseen-layout experiment of
the ``generalisation`` block (``unseen``: ``generalisation/results``, ``generalisation/models``) and each further
one of ``unseen_experiments`` (``NAME``: ``generalisation/experiments/NAME/...``).
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from hnsdt.compose.config import Params
from hnsdt.stages.common import provenance

PAPER, UNSEEN = "paper", "unseen"
MAX_MADE_AGAIN = 20  # episodes one replay makes again (each a run of its method and seed)


@dataclass(frozen=True)
class Found:
    """An evaluated episode: its experiment, its row of that evaluation's ``table`` (episodes.csv) and the
    checkpoints it was evaluated with."""

    experiment: str
    row: pd.Series
    table: Path
    models: Path

    @property
    def recorded(self) -> Path | None:
        """The .rrd the evaluation kept of it, if any (the paper protocol records the first episodes of a cell)."""
        rrd = self.row.get("rrd", "")
        return self.table.parent.parent / rrd if isinstance(rrd, str) and rrd else None


def check_recording(rrd: Path) -> None:
    """A kept recording is the bytes the evaluation wrote, checked before it is handed out: the ``.rrd`` passes
    ``rerun rrd verify``, the ``.mcap`` beside it reads to its end and its data section matches the CRC its writer
    recorded (a flipped bit in an image passes the reader otherwise). Raises ValueError naming the file."""
    import io
    import shutil
    import subprocess
    import sys
    import zlib

    from mcap.records import DataEnd, Footer
    from mcap.stream_reader import StreamReader

    def damaged(path: Path, why: str) -> ValueError:
        return ValueError(f"recording {path} is damaged ({why}): `dvc checkout` restores the committed recordings "
                          "from DVC's cache; or delete it, and `hnsdt replay` of this episode records it anew")

    for path in (rrd, rrd.with_suffix(".mcap")):
        if not path.is_file():
            raise damaged(path, "missing")
    rerun = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")
    verify = subprocess.run([rerun, "rrd", "verify", str(rrd)], capture_output=True, text=True)
    if verify.returncode != 0:
        raise damaged(rrd, "`rerun rrd verify` fails: " + " ".join((verify.stderr or verify.stdout).split())[:200])
    mcap = rrd.with_suffix(".mcap")
    data = mcap.read_bytes()
    try:
        records = list(StreamReader(io.BytesIO(data), skip_magic=False, validate_crcs=True).records)
        footer = next(r for r in records if isinstance(r, Footer))
        crc = next(r for r in records if isinstance(r, DataEnd)).data_section_crc
    except Exception as e:  # noqa: BLE001  (the mcap reader raises many kinds on a damaged file)
        raise damaged(mcap, f"unreadable: {type(e).__name__}") from None
    if crc and zlib.crc32(data[:footer.summary_start - 13]) != crc:  # (13: the DataEnd record itself)
        raise damaged(mcap, "its data section does not match the CRC its writer recorded")


def experiments(params: Params) -> dict[str, tuple[Path, Path]]:
    """Every experiment of ``params`` -> its results and models folders, as the pipeline writes them."""
    out = {PAPER: (Path("results"), Path("models")),
           UNSEEN: (Path("generalisation/results"), Path("generalisation/models"))}
    for name in params.unseen_experiments or {}:
        root = Path("generalisation/experiments") / name
        out[name] = (root / "results", root / "models")
    return out


def find_episodes(params: Params, pattern: str, experiment: str | None = None, results: Path | None = None,
                  models: Path | None = None) -> list[Found]:
    """The evaluated episodes whose id is ``pattern`` (or matches it, ``*`` and ``?`` as in a shell), in the
    named ``experiment``'s results (default: every experiment's), or in the ``results`` folder of an evaluation
    run elsewhere (``hnsdt generalisation evaluate --out``); an id found in several experiments must be named."""
    known = experiments(params)
    if experiment is not None and experiment not in known:
        raise ValueError(f"--experiment {experiment!r}: not an experiment here (the params': {', '.join(known)})")
    if results is not None:
        kind = experiment or (PAPER if "env" in _columns(Path(results) / "episodes.csv") else UNSEEN)
        places = {kind: (Path(results), models or known[kind][1])}
    else:
        places = {name: (res, models or mod) for name, (res, mod) in known.items()
                  if experiment in (None, name)}
    tables = {name: (res / "episodes.csv", mod) for name, (res, mod) in places.items()
              if (res / "episodes.csv").is_file()}
    if not tables:
        where = ", ".join(str(res / "episodes.csv") for res, _ in places.values())
        raise FileNotFoundError(f"no evaluation results at {where} (run `dvc repro`, or point --results at an "
                                "evaluation's folder)")
    found, example = [], ""
    for name, (path, mod) in tables.items():
        table = pd.read_csv(path, keep_default_na=False)
        example = example or table.episode_id.iloc[0]
        hits = table[table.episode_id == pattern]
        if hits.empty and any(c in pattern for c in "*?["):
            hits = table[[fnmatch.fnmatchcase(i, pattern) for i in table.episode_id]]
        found += [Found(name, row, path, mod) for _, row in hits.iterrows()]
    if not found:
        raise ValueError(f"no episode {pattern!r} in {', '.join(str(p) for p, _ in tables.values())} (ids are "
                         f"METHOD/LAYOUT/fpP/seedK/epI, e.g. {example!r}; a pattern such as '*/keydoor/fp0.1/seed0/ep0' "
                         "selects several)")
    named = sorted({f.experiment for f in found})
    if len(named) > 1 and not any(c in pattern for c in "*?["):
        raise ValueError(f"{pattern!r} is an episode of several experiments ({', '.join(named)}): name one with "
                         "--experiment")
    again = sum(f.recorded is None for f in found)
    if again > MAX_MADE_AGAIN:
        raise ValueError(f"{pattern!r} matches {len(found)} episodes, {again} of them not recorded: at most "
                         f"{MAX_MADE_AGAIN} are made again at once (name one cell's episode, e.g. "
                         "'*/keydoor/fp0.1/seed3/ep5')")
    return found


def _columns(path: Path) -> list[str]:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no evaluation results there")
    return list(pd.read_csv(path, nrows=0).columns)


def record_again(params: Params, found: Found, threads: int = 1) -> dict[str, bytes]:
    """``found`` made again as its evaluation ran it and checked against its row: its .rrd and .mcap bytes."""
    from hnsdt.compose.config import unseen_experiment

    if found.experiment == PAPER:
        return replay_evaluated(params, found.models, found.row, found.table, threads)
    experiment_params = unseen_experiment(params, None if found.experiment == UNSEEN else found.experiment)
    return replay_unseen(experiment_params, found.models, found.row, found.table, threads)


def replay_unseen(params: Params, models: Path, row, table_path: Path, threads: int = 1) -> dict[str, bytes]:
    """An evaluated unseen-layout episode (``row`` of ``table_path``) made again and recorded
    (:func:`hnsdt.evaluation.layouts.rerun_layout_episode`), checked against its row; its .rrd and .mcap bytes."""
    from hnsdt.compose import generalisation as gen
    from hnsdt.compose.config import eval_epsilon, layout_executor
    from hnsdt.evaluation.layouts import rerun_layout_episode

    fps = tuple(float(f) for f in params.need("evaluate").fail_probs)
    sources = tuple(gen.layout_splits(params, evaluated_only=True))
    outcome, files = rerun_layout_episode(sources, fps, params.need("generalisation").episodes, models,
                                          row["method"], int(row["seed"]), layout_executor(params, row["method"]),
                                          eval_epsilon(params, row["method"]), row["split"], row["layout"],
                                          float(row["fail_prob"]), int(row["episode"]), threads,
                                          provenance(params))
    outcome["reward"] = float(f"{outcome['reward']:.6g}")  # (as episodes.csv writes it)
    _check_outcome(row["episode_id"], outcome, row, table_path)
    return files


def replay_evaluated(params: Params, models: Path, row, table_path: Path, threads: int = 1) -> dict[str, bytes]:
    """An evaluated episode of the paper protocol (``row`` of ``table_path``, its episodes.csv) made again
    (:func:`hnsdt.evaluation.paper.rerun_episode`), checked against its row; its .rrd and .mcap bytes."""
    from hnsdt.compose.config import env_spec, evaluate_settings, executor_config
    from hnsdt.core.methods import ARMS
    from hnsdt.evaluation.paper import Cell, rerun_episode

    settings = evaluate_settings(params)
    if row["env"] not in settings.envs:
        raise ValueError(f"{row['episode_id']}: env {row['env']} is not in train.envs of the params")
    outcome, files = rerun_episode(settings, {e: env_spec(params, e) for e in settings.envs},
                                   {arm: executor_config(params, arm) for arm in ARMS}, models,
                                   Cell(row["method"], row["env"], float(row["fail_prob"]), int(row["seed"])),
                                   int(row["episode"]), threads, provenance(params))
    _check_outcome(row["episode_id"], outcome, row, table_path)
    return files


def _check_outcome(episode_id: str, outcome: dict, row, table_path: Path) -> None:
    """An episode made again must end as its row of the evaluation says."""
    listed = {key: type(value)(row[key]) for key, value in outcome.items()}
    if outcome != listed:
        raise ValueError(f"{episode_id} ran again to {outcome}, not to {listed} as in {table_path}: the models, "
                         "params, maps or code changed since that evaluation (`dvc status` says which, for the "
                         "pipeline's own)")
