"""The decision transformer's linear layers on NumPy's OpenBLAS (hnsdt/models/kernels.py)."""

import os
import subprocess
import sys

import pytest
import torch
import torch.nn.functional as F

from hnsdt.models.kernels import blas_core, linear


@pytest.mark.parametrize("shape", [(7, 16), (3, 5, 16), (1, 16), (2, 0, 16)])
@pytest.mark.parametrize("bias", [True, False])
def test_linear_is_torchs_linear_forward_and_backward(shape, bias):
    torch.manual_seed(0)
    x = torch.randn(*shape, requires_grad=True)
    w = torch.randn(12, 16, requires_grad=True)
    b = torch.randn(12, requires_grad=True) if bias else None
    ours = linear(x, w, b)
    ours.square().sum().backward()
    grads = [t.grad.clone() for t in (x, w, b) if t is not None]
    for t in (x, w, b):
        if t is not None:
            t.grad = None
    theirs = F.linear(x, w, b)
    theirs.square().sum().backward()
    assert ours.shape == theirs.shape and ours.dtype == torch.float32
    torch.testing.assert_close(ours, theirs)
    for mine, torchs in zip(grads, [t.grad for t in (x, w, b) if t is not None]):
        torch.testing.assert_close(mine, torchs)


def test_linear_gradients_are_exact_derivatives():
    torch.manual_seed(0)
    x, w, b = (torch.randn(*s, dtype=torch.float64, requires_grad=True) for s in ((4, 3, 6), (5, 6), (5,)))
    assert torch.autograd.gradcheck(linear, (x, w, b))


def test_only_the_inputs_that_need_gradients_get_them():
    x, w = torch.randn(4, 6), torch.randn(5, 6, requires_grad=True)
    linear(x, w).sum().backward()
    assert x.grad is None and w.grad is not None
    with torch.no_grad():
        assert not linear(x, w).requires_grad


def test_the_tests_run_the_pinned_kernels():
    # conftest.py pins OPENBLAS_CORETYPE before NumPy loads, as the stage scripts do (hnsdt/core/reproducible.py)
    assert os.environ["OPENBLAS_CORETYPE"] == "Haswell"
    assert blas_core() == "Haswell"


def test_a_core_type_set_after_numpy_loaded_is_one_clear_error():
    code = ("import numpy, os, torch\n"
            "os.environ['OPENBLAS_CORETYPE'] = 'Sandybridge'\n"  # too late: OpenBLAS chose its kernels at load
            "from hnsdt.models.kernels import linear\n"
            "linear(torch.ones(2, 3), torch.ones(4, 3))\n")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode != 0
    assert "not OPENBLAS_CORETYPE=Sandybridge" in out.stderr.strip().splitlines()[-1]


def test_native_mode_drops_the_kernel_pins_but_keeps_one_blas_thread(monkeypatch):
    from hnsdt.core.reproducible import ALWAYS, PINNED_CPU, pinned_environment

    monkeypatch.setenv("HNSDT_CPU", "native")
    assert pinned_environment() == ALWAYS and ALWAYS["OPENBLAS_NUM_THREADS"] == "1"
    monkeypatch.delenv("HNSDT_CPU")
    assert pinned_environment() == ALWAYS | PINNED_CPU and PINNED_CPU["OPENBLAS_CORETYPE"] == "Haswell"
