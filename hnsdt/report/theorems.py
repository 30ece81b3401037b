"""The section on the paper's two theorems, checked on the measurements (:mod:`hnsdt.evaluation.theorems`)."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from hnsdt.compose.params import Params
from hnsdt.core.methods import PROPOSED
from hnsdt.report.common import fmt


def _largest_informative_d(m: int, K: int, delta: float) -> float:
    """The largest VC-dimension proxy for which Theorem 2's bound is still above 0 (bisection)."""
    from hnsdt.evaluation.theorems import pac_bound

    if pac_bound(m, K, 1e-6, delta) <= 0:
        return 0.0
    lo, hi = 1e-6, float(max(m, 1))
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if pac_bound(m, K, mid, delta) > 0 else (lo, mid)
    return lo


def theorem_sections(params: Params, results: Path, summ: pd.DataFrame, episodes: pd.DataFrame) -> tuple[dict, dict]:
    """The two theorems checked on the measurements: the template's context for their sections (empty when
    the inputs are missing) and their rows for ``theorems.json``."""
    from hnsdt.compose.config import env_spec
    from hnsdt.evaluation.theorems import theorem1, theorem2
    from hnsdt.envs.oracle import optimum

    if not (results / "segments.csv").is_file() or "regret" not in summ or params.theorems is None:
        return {}, {}
    ts = params.theorems.model_dump()
    segments = pd.read_csv(results / "segments.csv")
    envs = {e: env_spec(params, e) for e in sorted(set(segments.env))}
    counts = pd.read_csv(results / "training_segments.csv")
    n_params = json.loads((results / "model_parameters.json").read_text())
    v_star = {(env, f): optimum(envs[env].layout, f, envs[env].max_steps, ts["gamma"]).ret
              for env, f in set(zip(segments.env, segments.fail_prob))}
    t1 = theorem1(segments, episodes, v_star, ts["gamma"], ts["B"])
    t2_parts = []
    for env in sorted(set(segments.env)):
        d = n_params.get(f"{env}/{PROPOSED}", float("nan")) if ts["vc_dimension"] == "parameters" else ts["vc_dimension"]
        part = theorem2(segments[segments.env == env], episodes, counts, float(d), ts["delta"])
        part["d_max_informative"] = [_largest_informative_d(r.m, r.K, ts["delta"]) for r in part.itertuples()]
        t2_parts.append(part)
    t2 = pd.concat(t2_parts, ignore_index=True) if t2_parts else pd.DataFrame()
    t1_lines = ["| env | fail_prob | ε_sym | ε_exec | ρ | bound | V*_γ | V^HNSDT_γ | measured regret | holds | "
                "bound / measured |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    t1_lines += [f"| {r.env} | {r.fail_prob:g} | {r.eps_sym:.3f} | {r.eps_exec:.4f} | {r.rho:.3f} | {r.bound:.2f} | "
                 f"{r.v_star:.4f} | {r.v_method:.4f} | {r.measured_regret:.4f} | {'yes' if r.holds else 'NO'} | "
                 f"{fmt(r.looseness, '.0f')} |" for r in t1.itertuples()]
    t2_lines = ["| env | fail_prob | m | K | d | PAC lower bound | measured | holds | largest d with a bound > 0 |",
                "|---|---|---|---|---|---|---|---|---|"]
    t2_lines += [f"| {r.env} | {r.fail_prob:g} | {r.m} | {r.K} | {r.d:.0f} | {fmt(r.bound)} | {r.measured:.3f} | "
                 f"{'yes' if r.holds else 'NO'} | {r.d_max_informative:.2f} |" for r in t2.itertuples()]
    context = {"gamma": f"{ts['gamma']:g}", "B": f"{ts['B']:g}", "delta": f"{ts['delta']:g}",
               "d_name": ("the number of HNSDT parameters" if ts["vc_dimension"] == "parameters"
                          else ts["vc_dimension"]),
               "theorem1": t1_lines, "theorem1_holds": int(t1.holds.sum()), "theorem1_cells": len(t1),
               "theorem2": t2_lines}
    data = {"theorem1": t1.to_dict(orient="records"), "theorem2": t2.to_dict(orient="records")}
    return context, data
