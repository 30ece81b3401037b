"""The networks: the decision transformer (dt), the recurrent and Q networks of the baselines, DT training and
checkpoints that carry their own architecture."""
