"""The learned networks' matrix products and elementwise functions on kernels pinned by name, not by vendor.

Why: a model's bytes depend on the kernels that computed it. torch's CPU GEMMs are MKL's, which dispatches by
vendor and ISA, so the pipeline pins them to ``MKL_CBWR=COMPATIBLE`` (:mod:`hnsdt.core.reproducible`): slow SSE2
code, and even so AMD and Intel CPUs trained other weights from the same seeds (docs/reproducibility.md). NumPy's
OpenBLAS picks its kernels by core type, and ``OPENBLAS_CORETYPE=Haswell`` (pinned beside MKL's setting) runs the
same AVX2/FMA kernels with the same blocking on any x86-64 CPU that has AVX2, Intel or AMD, faster than the pinned
MKL (``benchmarks/cpu_determinism.py`` measures both). torch's GELU runs on oneDNN's JIT code, chosen by ISA, and its
elementwise ``erf``, ``exp``, ``log``, ``tanh`` and ``sqrt`` on MKL's vector maths (VML), whose bytes follow MKL's
mode and the CPU's vendor.

:func:`linear` (and :class:`Linear`, an ``nn.Linear`` computed by it), :func:`matmul` and :func:`attention` are
torch's products computed there, forward and backward (autograd functions), for CPU tensors; :func:`gelu` is the
exact GELU on torch's own kernel, :func:`tanh` and :func:`sqrt` torch's functions off VML. Other devices keep
torch's kernels. Same numbers up to rounding (tested); the bytes are OpenBLAS's and torch's vectorised kernels'
(``ATEN_CPU_CAPABILITY``), none MKL's or oneDNN's: a model built from these parts trains the same bytes whatever
MKL or oneDNN is asked to do (tested).
"""

from __future__ import annotations

import ctypes
import glob
import os
from functools import lru_cache

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F


@lru_cache(maxsize=1)
def blas_core() -> str:
    """The core type whose kernels NumPy's OpenBLAS runs in this process (``OPENBLAS_CORETYPE``, read when NumPy
    loads it), e.g. ``Haswell``; ``unknown`` for a NumPy built on another BLAS."""
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "libscipy_openblas*.so"))
    for path in libs:
        lib = ctypes.CDLL(path)  # the library NumPy already loaded (dlopen returns the same handle)
        for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename"):
            if hasattr(lib, name):
                getattr(lib, name).restype = ctypes.c_char_p
                return getattr(lib, name)().decode()
    return "unknown"


@lru_cache(maxsize=1)  # (once per process: it raises until it passes)
def check_blas_core() -> None:
    """Fail with one line where the pinned environment asks for a core type NumPy's OpenBLAS does not run (NumPy
    was imported before the variable was set): its products would give other bytes."""
    wanted = os.environ.get("OPENBLAS_CORETYPE")
    if wanted and blas_core().lower() != wanted.lower():
        raise RuntimeError(f"NumPy's OpenBLAS runs {blas_core()} kernels, not OPENBLAS_CORETYPE={wanted}: set the "
                           "pinned environment (hnsdt.core.reproducible) before NumPy is imported")


def _matrix(t: torch.Tensor) -> np.ndarray:
    """(…, k) tensor -> (rows, k) C-contiguous array, sharing memory where it can."""
    return t.detach().reshape(-1, t.shape[-1]).contiguous().numpy()


def _rows(x: torch.Tensor, weight: torch.Tensor) -> np.ndarray:
    """``x`` as the rows the product reads: (rows, k), or (stack, rows, k) for a stack of weights."""
    if weight.dim() == 2:
        return _matrix(x)
    return x.detach().reshape(weight.shape[0], -1, x.shape[-1]).contiguous().numpy()


def _forward(x, weight, bias) -> torch.Tensor:
    # a stack's products one matrix each (numpy's matmul runs one GEMM per matrix of the stack): each network of a
    # stack gets the bytes it would get alone
    y = np.matmul(_rows(x, weight), weight.detach().numpy().swapaxes(-1, -2))
    if bias is not None:
        y += bias.detach().numpy()[..., None, :] if weight.dim() == 3 else bias.detach().numpy()
    return torch.from_numpy(y).reshape(*x.shape[:-1], weight.shape[-2])


class _Linear(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, weight, bias):
        ctx.save_for_backward(x, weight)
        return _forward(x, weight, bias)

    @staticmethod
    def backward(ctx, grad):
        x, weight = ctx.saved_tensors
        g = _rows(grad, weight)
        grad_x = torch.from_numpy(np.matmul(g, weight.numpy())).reshape(x.shape) if ctx.needs_input_grad[0] else None
        grad_w = torch.from_numpy(np.matmul(g.swapaxes(-1, -2), _rows(x, weight))) if ctx.needs_input_grad[1] else None
        grad_b = torch.from_numpy(g.sum(-2)) if ctx.needs_input_grad[2] else None  # (False without a bias)
        return grad_x, grad_w, grad_b


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None) -> torch.Tensor:
    """``F.linear(x, weight, bias)``, on OpenBLAS for CPU tensors (float32 or float64). A stack of weights (S, out,
    in) and biases (S, out), several networks' layers side by side (:func:`hnsdt.baselines.online.stack_networks`), maps
    (S, …, in) to (S, …, out), each network's inputs through its own weights."""
    if weight.dim() == 3:  # (autograd or not: one path; torch has no stacked linear)
        if x.device.type != "cpu":
            y = torch.matmul(x.reshape(weight.shape[0], -1, x.shape[-1]), weight.transpose(-1, -2))
            return (y if bias is None else y + bias[:, None, :]).reshape(*x.shape[:-1], weight.shape[-2])
        check_blas_core()
        return _Linear.apply(x, weight, bias)
    if x.device.type != "cpu":
        return F.linear(x, weight, bias)
    check_blas_core()
    if torch.is_grad_enabled() and any(t is not None and t.requires_grad for t in (x, weight, bias)):
        return _Linear.apply(x, weight, bias)
    return _forward(x, weight, bias)  # (acting: no autograd node to build)


class Linear(nn.Linear):
    """``nn.Linear`` (the same parameters and state dict) whose product is :func:`linear`."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return linear(x, self.weight, self.bias)


def _array(t: torch.Tensor) -> np.ndarray:
    return t.detach().contiguous().numpy()


class _MatMul(torch.autograd.Function):
    @staticmethod
    def forward(ctx, a, b):
        ctx.save_for_backward(a, b)
        return torch.from_numpy(np.matmul(_array(a), _array(b)))

    @staticmethod
    def backward(ctx, grad):
        a, b = ctx.saved_tensors
        g = _array(grad)
        grad_a = torch.from_numpy(np.matmul(g, _array(b).swapaxes(-1, -2))) if ctx.needs_input_grad[0] else None
        grad_b = torch.from_numpy(np.matmul(_array(a).swapaxes(-1, -2), g)) if ctx.needs_input_grad[1] else None
        return grad_a, grad_b


def matmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a @ b`` of (…, m, k) and (…, k, n) float tensors of one batch shape, on OpenBLAS for CPU tensors."""
    if a.device.type != "cpu":
        return a @ b
    check_blas_core()
    if torch.is_grad_enabled() and (a.requires_grad or b.requires_grad):
        return _MatMul.apply(a, b)
    return torch.from_numpy(np.matmul(_array(a), _array(b)))


def attention(q, k, v, mask: torch.Tensor, dropout_p: float = 0.0) -> torch.Tensor:
    """``F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=dropout_p)`` (``mask`` additive), its
    two products on :func:`matmul`."""
    weights = torch.softmax(matmul(q, k.transpose(-1, -2)) * q.shape[-1] ** -0.5 + mask, dim=-1)
    return matmul(F.dropout(weights, dropout_p) if dropout_p > 0 else weights, v)


class _without_onednn:
    """torch's own CPU kernels for the ops inside (``F.gelu`` and its backward otherwise run oneDNN's JIT code, whose
    bytes follow the ISA oneDNN picks). The flag is the process's: set and restored around one op. (Not
    ``torch.backends.mkldnn.flags``: it also sets oneDNN's TF32 flag, which warns on every entry on a CPU build.)"""

    def __enter__(self):
        self.was = torch._C._get_mkldnn_enabled()
        torch._C._set_mkldnn_enabled(False)

    def __exit__(self, *exc):
        torch._C._set_mkldnn_enabled(self.was)


class _GELU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x):
        ctx.save_for_backward(x)
        with _without_onednn():
            return F.gelu(x)

    @staticmethod
    def backward(ctx, grad):
        (x,) = ctx.saved_tensors
        with _without_onednn():
            return torch.ops.aten.gelu_backward(grad.contiguous(), x)


def gelu(x: torch.Tensor) -> torch.Tensor:
    """``F.gelu(x)`` (the exact, erf form), forward and backward on torch's own vectorised kernel for CPU tensors:
    ``F.gelu`` runs oneDNN's JIT code (bytes by ISA), and ``torch.erf`` MKL's vector maths (bytes by MKL's mode
    and the CPU's vendor)."""
    if x.device.type != "cpu":
        return F.gelu(x)
    return _GELU.apply(x)


def tanh(x: torch.Tensor) -> torch.Tensor:
    """``torch.tanh(x)`` up to rounding, as ``2 σ(2x) − 1``: torch's CPU ``tanh`` (like ``exp``, ``log``, ``erf`` and
    ``sqrt``) runs MKL's vector maths, whose bytes follow MKL's mode and the CPU; ``sigmoid`` is torch's own."""
    if x.device.type != "cpu":
        return torch.tanh(x)
    return 2 * torch.sigmoid(2 * x) - 1


def sqrt(x: torch.Tensor) -> torch.Tensor:
    """``torch.sqrt(x)``, correctly rounded (NumPy's, the IEEE square root every x86-64 CPU computes alike) for CPU
    tensors: torch's runs MKL's vector maths, which round some float32 roots otherwise, by CPU and MKL mode."""
    if x.device.type != "cpu":
        return torch.sqrt(x)
    return torch.from_numpy(np.sqrt(_array(x))).reshape(x.shape)
