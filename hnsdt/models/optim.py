"""torch's Adam, stepped without importing ``torch._dynamo``.

Why: ``torch.optim`` wraps ``Optimizer.step``, ``zero_grad``, ``add_param_group`` and ``(load_)state_dict`` so that
``torch.compile`` can trace around them, and the wrappers import ``torch._dynamo`` on their first call: 1.2 s of
every training process here (a stage runs one process and its workers; the tests start dozens). This package never
compiles, so :class:`Adam` calls the wrapped methods themselves: the same update, the same bytes (tested against
``torch.optim.Adam``), no compiler import.
"""

from __future__ import annotations

from inspect import unwrap

import torch

_Optimizer = torch.optim.Optimizer


class Adam(torch.optim.Adam):
    """``torch.optim.Adam``; each dynamo-wrapped method calls the function torch wrapped (``inspect.unwrap``)."""

    def add_param_group(self, param_group: dict) -> None:
        unwrap(_Optimizer.add_param_group)(self, param_group)

    def zero_grad(self, set_to_none: bool = True) -> None:
        unwrap(_Optimizer.zero_grad)(self, set_to_none)

    def state_dict(self) -> dict:
        return unwrap(_Optimizer.state_dict)(self)

    def load_state_dict(self, state_dict: dict) -> None:
        unwrap(_Optimizer.load_state_dict)(self, state_dict)

    @torch.no_grad()  # what torch's wrapper sets for a non-differentiable optimizer, less its compiler graph breaks
    def step(self, closure=None):
        return unwrap(torch.optim.Adam.step)(self, closure)
