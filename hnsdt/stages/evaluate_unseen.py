"""Stage `evaluate_generalisation`: every method of the unseen-layout experiment on every evaluated split."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from hnsdt.compose.config import Params, compute_settings


def evaluate_unseen(params: Params, models: Path, out: Path, compute=None, progress: bool = True,
                    splits: Sequence[str] | None = None, methods: Sequence[str] | None = None):
    """Stage `evaluate_generalisation`: every method × its seeds on every evaluated layout (training, held-out,
    MiniGrid, drawn), the symbolic baseline as the reference, beside the exact optimum; ``splits`` and ``methods``
    name the splits and learned methods to evaluate (default: every one; each episode is the one it is in the
    whole evaluation)."""
    from hnsdt.compose import generalisation as gen
    from hnsdt.compose.config import eval_epsilon, layout_executor
    from hnsdt.core.methods import REFERENCE
    from hnsdt.evaluation.layouts import layout_evaluation
    from hnsdt.evaluation.runs import evaluate

    g = params.need("generalisation")
    fps = tuple(float(f) for f in params.need("evaluate").fail_probs)
    sources = tuple(gen.layout_splits(params, evaluated_only=True))
    if splits:
        named = list(dict.fromkeys(s.split for s in sources))
        unknown = [s for s in splits if s not in named]
        if unknown:
            raise ValueError(f"--splits: no split {', '.join(unknown)} here (the experiment's: {', '.join(named)})")
    unknown = [m for m in methods or [] if m not in g.learned]
    if unknown:
        raise ValueError(f"--methods: {', '.join(unknown)} not learned here (the experiment's: {', '.join(g.learned)})")
    gen.check_sources(sources, max(fps))
    evaluated = [*(m for m in g.learned if not methods or m in methods), REFERENCE]
    plan = layout_evaluation({m: g.seeds_of(m) for m in evaluated}, sources, fps, g.episodes,
                             {m: layout_executor(params, m) for m in evaluated},  # (generalisation.operators)
                             {m: eval_epsilon(params, m) for m in evaluated}, models, splits or None)
    table = evaluate(plan, out, compute or compute_settings(params), progress)
    print(f"wrote {out}/episodes.csv ({len(table)} episodes), summary.csv, segments.csv, layouts.csv")
    return table
