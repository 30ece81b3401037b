"""torch's Adam, stepped without importing ``torch._dynamo`` and with a correctly rounded square root.

Why: ``torch.optim`` wraps ``Optimizer.step``, ``zero_grad``, ``add_param_group`` and ``(load_)state_dict`` so that
``torch.compile`` can trace around them, and the wrappers import ``torch._dynamo`` on their first call: 1.2 s of
every training process here (a stage runs one process and its workers; the tests start dozens). This package never
compiles, so :class:`Adam` calls the wrapped methods themselves. And torch's update takes the square root of the
second moment with ``torch.sqrt``, which on the CPU is MKL's vector maths: its roots are not all correctly rounded,
and which ones are follows MKL's mode and the CPU (``hnsdt.models.kernels.sqrt``). :meth:`Adam.step` is torch's
update (``_single_tensor_adam``, the path torch takes for CPU tensors) with the exact root: the same state, the
same numbers up to that rounding (tested).
"""

from __future__ import annotations

from inspect import unwrap

import torch

from hnsdt.models.kernels import sqrt

_Optimizer = torch.optim.Optimizer


class Adam(torch.optim.Adam):
    """``torch.optim.Adam`` with its defaults' options (no AMSGrad, not maximising); each dynamo-wrapped method calls
    the function torch wrapped (``inspect.unwrap``)."""

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
        loss = None
        if closure is not None:
            with torch.enable_grad():
                loss = closure()
        for group in self.param_groups:
            if group["amsgrad"] or group["maximize"] or group["decoupled_weight_decay"]:
                raise ValueError("hnsdt.models.optim.Adam steps plain Adam: no amsgrad, maximize or decoupled decay")
            beta1, beta2 = group["betas"]
            for param in group["params"]:
                if param.grad is None:
                    continue
                state = self.state[param]
                if not state:  # torch's own state layout, so that state dicts load either way
                    state["step"] = torch.tensor(0.0)
                    state["exp_avg"] = torch.zeros_like(param, memory_format=torch.preserve_format)
                    state["exp_avg_sq"] = torch.zeros_like(param, memory_format=torch.preserve_format)
                grad = param.grad
                if group["weight_decay"]:
                    grad = grad.add(param, alpha=group["weight_decay"])
                state["step"] += 1
                step = state["step"].item()
                state["exp_avg"].lerp_(grad, 1 - beta1)
                state["exp_avg_sq"].mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
                step_size = group["lr"] / (1 - beta1 ** step)
                denom = (sqrt(state["exp_avg_sq"]) / (1 - beta2 ** step) ** 0.5).add_(group["eps"])
                param.addcdiv_(state["exp_avg"], denom, value=-step_size)
        return loss
