"""hnsdt: Hierarchical Neuro-Symbolic Decision Transformer, reproduced.

The package follows the paper's Figure 1: ``envs`` (environment) → ``symbolic`` (abstraction φ, planner,
sub-goals ψ) → ``data`` (segmented LeRobot datasets) → ``models`` (decision transformer) → ``agents``; beside
them ``baselines`` (the compared learners), ``evaluation`` and ``logs`` (replay files), ``training`` and
``generalisation`` (the unseen-layout experiment's splits), and ``core``, what every stage runs on (params,
settings, method registry, stages, compute).
"""

import hnsdt.envs  # noqa: F401  (registers the gymnasium ids)

__version__ = "0.1.0"
