"""The base of every trained network: what the method registry and the checkpoints need to know of it."""

from __future__ import annotations

import torch.nn as nn


class Network(nn.Module):
    """A model with its config: ``class X(Network, arch="name", config=XConfig)``. ``arch`` names the
    architecture in checkpoints (:mod:`hnsdt.models.checkpoint`), ``config_class`` the dataclass that rebuilds
    it; ``self.cfg`` holds the instance's config."""

    arch: str
    config_class: type
    stack_size: int = 0  # > 0: the parameters are a stack of that many networks' (hnsdt.baselines.online)

    def __init_subclass__(cls, arch: str, config: type, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.arch, cls.config_class = arch, config

    def __init__(self, cfg):
        super().__init__()
        self.cfg = cfg

    def model_states(self, layout, obs):
        """The state vectors this model reads, from the environment's observations and the layout (here: the
        observations as they are; the view networks of :mod:`hnsdt.models.view` add the grid around the agent)."""
        return obs
