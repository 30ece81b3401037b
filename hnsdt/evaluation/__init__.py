"""Evaluation of every method x env x fail_prob x seed (evaluate), the theorem checks and the report."""
