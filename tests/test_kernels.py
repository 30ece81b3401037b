"""The learned networks' products on NumPy's OpenBLAS, and GELU off oneDNN (hnsdt/models/kernels.py)."""

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from hnsdt.models.kernels import attention, blas_core, gelu, linear, matmul, sqrt, tanh


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


def test_matmul_attention_and_gelu_are_torchs_forward_and_backward():
    torch.manual_seed(0)
    q, k, v = (torch.randn(2, 4, 5, 8, requires_grad=True) for _ in range(3))
    mask = torch.zeros(5, 5).masked_fill(torch.ones(5, 5, dtype=torch.bool).triu(1), float("-inf"))

    def both(f, g, inputs):
        ours = f(*inputs)
        ours.square().sum().backward()
        grads = [t.grad.clone() for t in inputs]
        for t in inputs:
            t.grad = None
        theirs = g(*inputs)
        theirs.square().sum().backward()
        torch.testing.assert_close(ours, theirs)
        for mine, torchs in zip(grads, [t.grad for t in inputs]):
            torch.testing.assert_close(mine, torchs)
        for t in inputs:
            t.grad = None

    both(matmul, torch.matmul, (q, k.detach().transpose(-1, -2).requires_grad_()))
    both(lambda *t: attention(*t, mask), lambda *t: F.scaled_dot_product_attention(*t, attn_mask=mask), (q, k, v))
    both(gelu, F.gelu, (q,))
    with torch.no_grad():
        assert not matmul(q, k.transpose(-1, -2)).requires_grad


def test_tanh_is_torchs_and_sqrt_is_correctly_rounded():
    torch.manual_seed(0)
    x = torch.randn(64, 33) * 4
    torch.testing.assert_close(tanh(x), torch.tanh(x), rtol=0, atol=3e-7)
    a = x.abs() + 1e-3
    exact = torch.from_numpy(np.sqrt(a.numpy().astype(np.float64)).astype(np.float32))  # the float64 root, rounded
    assert torch.equal(sqrt(a), exact) and sqrt(a[:, ::2]).shape == (64, 17)


def test_matmul_gradients_are_exact_derivatives():
    torch.manual_seed(0)
    a, b = (torch.randn(*s, dtype=torch.float64, requires_grad=True) for s in ((3, 4, 6), (3, 6, 2)))
    assert torch.autograd.gradcheck(matmul, (a, b))


TRAIN_A_FEW_STEPS = """
import hashlib, sys, numpy as np, torch
import hnsdt
from hnsdt.baselines.dqn import DQNConfig, train_dqn
from hnsdt.baselines.options import OptionsConfig, train_options
from hnsdt.envs import load_layout
from hnsdt.models.dt import DecisionTransformer, DTConfig
from hnsdt.models.optim import Adam
from hnsdt.models.qnetwork import OptionCriticConfig, QNetworkConfig
torch.manual_seed(0)
g = np.random.default_rng(0)
dt = DecisionTransformer(DTConfig("subgoal", 1, 5, 5, context=4, n_layers=2, d_model=32, n_heads=2,
                                  formulation="episode"))
opt = Adam(dt.parameters(), 1e-3)
B, T = 4, 9
for _ in range(3):
    st = np.stack([g.integers(0, 5, (B, T)), g.integers(0, 5, (B, T)), g.integers(0, 2, (B, T))], -1)
    batch = dict(states=torch.from_numpy(st), actions=torch.from_numpy(g.integers(0, 5, (B, T))),
                 timesteps=torch.from_numpy(np.tile(np.arange(T), (B, 1))),
                 subgoal_ids=torch.from_numpy(g.integers(0, 3, (B, T))),
                 subgoal_targets=torch.from_numpy(g.integers(-1, 5, (B, T, 2))),
                 loss_mask=torch.ones(B, T, dtype=torch.bool))
    loss = dt.loss(batch)
    opt.zero_grad()
    loss.backward()
    opt.step()
lay = load_layout("keydoor_5x5")
q, _, _ = train_dqn(lay, 50, QNetworkConfig(lay.n_flags, *lay.shape),
                    DQNConfig(env_steps=400, learning_starts=200, batch_size=16, seed=0), progress=False)
oc, _, _ = train_options(lay, 50, OptionCriticConfig(lay.n_flags, *lay.shape),
                         OptionsConfig(env_steps=400, learning_starts=200, batch_size=16, seed=0), progress=False)
h = hashlib.sha256()
for model in (dt, q, oc):
    for t in model.state_dict().values():
        h.update(t.numpy().tobytes())
print("torch._dynamo" in sys.modules, h.hexdigest())
"""


@pytest.mark.slow  # (an end-to-end run: tests/conftest.py, pyproject.toml's markers)
def test_the_networks_bytes_do_not_follow_what_mkl_or_onednn_are_told():
    # MKL's COMPATIBLE mode still trained other weights on an AMD EPYC than on an Intel Xeon, GELU ran on oneDNN's
    # ISA-dependent code, and erf, exp and sqrt on MKL's vector maths (VML; only an Intel Xeon showed it): none may
    # reach a transformer's or a Q-network's bytes any more. (The DQN's
    # and the transformer's training imports no torch._dynamo: hnsdt.models.optim.Adam, 1.2 s per process.)
    digests = set()
    for mkl, onednn in [("COMPATIBLE", "AVX2"), ("AUTO", "AVX512_CORE_AMX")]:
        env = dict(os.environ, MKL_CBWR=mkl, DNNL_MAX_CPU_ISA=onednn)
        out = subprocess.run([sys.executable, "-c", TRAIN_A_FEW_STEPS], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr[-2000:]
        dynamo, digest = out.stdout.split()[-2:]
        assert dynamo == "False"
        digests.add(digest)
    assert len(digests) == 1
