"""Evaluation of every method × layout × fail_prob × seed against the exact optimum, the ablation table, and
the checks of the paper's two theorems."""
