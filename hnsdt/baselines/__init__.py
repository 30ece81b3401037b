"""The four learned baselines of the paper's comparison besides the pure DT (Section 5), and PPO.

* :mod:`.recurrent` — ``lstm_hier`` and ``gru``: recurrent behaviour cloning on the LeRobot dataset.
* :mod:`.dqn` — ``dqn``: deep Q-learning with replay and a target network, online.
* :mod:`.options` — ``options``: option-critic with 8 learned options, online.
* :mod:`.ppo` — ``ppo``: proximal policy optimisation, online (not in the paper: MiniGrid users' usual baseline).

Each module has a config dataclass of documented knobs, a ``train_*`` function that returns the model, its
training curve and the data it used, and a batched agent for :func:`hnsdt.agents.rollout.rollout`.
"""
