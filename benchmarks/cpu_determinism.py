"""Which CPU settings change the bytes of a trained model, and what pinning them costs.

Usage: python benchmarks/cpu_determinism.py
Each configuration runs in a fresh process: a decision transformer (L3, d128, context 10, the episode
formulation the pipeline trains: 32 episodes of 40 steps a batch) trained 30 steps on a fixed random batch
stream, option-critic trained 6,000 env steps on Case 1, and the RNN baselines (the LSTM hierarchical controller,
3 × 256, and the GRU, 2 × 128: torch's fused layers, whose training still runs on oneDNN and MKL) trained 10 steps
each on a fixed random stream of 16 episodes of 4-40 steps. It prints the hash of each model's weights (the two RNNs'
as one) and the time per step, then the throughput of one (100 x 128) . (128 x 512) product on one thread, torch's ``F.linear``
(MKL) against ``hnsdt.models.kernels.linear`` (NumPy's OpenBLAS), which computes the DT's and the Q-networks'
products since the MKL and oneDNN rows stopped mattering to them (2026-12-01). A row whose hash differs from the
first row's shows a setting that a different machine (another ISA, another vendor's MKL path, another BLAS core
type, another core count) would change; the last rows are what ``hnsdt/core/reproducible.py`` pins, and the last
line says whether they gave the hashes of the machine that made the committed lock (:data:`REFERENCE`).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

from hnsdt.core.reproducible import ALWAYS, PINNED_CPU

CHILD = r"""
import hashlib, time
import numpy as np, torch
import hnsdt
from hnsdt.envs import load_layout
from hnsdt.baselines.options import OptionsConfig, train_options
from hnsdt.models.dt import DecisionTransformer, DTConfig
from hnsdt.models.kernels import linear
from hnsdt.models.optim import Adam
from hnsdt.models.qnetwork import OptionCriticConfig
from hnsdt.models.recurrent import RecurrentConfig, RecurrentPolicy

def digest(*models):
    h = hashlib.sha256()
    for model in models:
        for v in model.state_dict().values():
            h.update(v.detach().cpu().numpy().tobytes())
    return h.hexdigest()[:12]

torch.manual_seed(0)
g = np.random.default_rng(0)
dt = DecisionTransformer(DTConfig("subgoal", 1, 5, 5, context=10, n_layers=3, formulation="episode"))
opt = Adam(dt.parameters(), 1e-3)
B, T, steps = 32, 40, 30
t = time.perf_counter()
for _ in range(steps):
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
dt_ms = (time.perf_counter() - t) / steps * 1000
lay = load_layout("keydoor_5x5")
t = time.perf_counter()
oc, _, _ = train_options(lay, 100, OptionCriticConfig(lay.n_flags, *lay.shape),
                         OptionsConfig(env_steps=6000, learning_starts=1000, seed=0), progress=False)
oc_s = time.perf_counter() - t

rnns, rnn_steps, B, T = [], 0, 16, 40
t = time.perf_counter()
for cell, layers, hidden, hierarchical in (("lstm", 3, 256, True), ("gru", 2, 128, False)):
    torch.manual_seed(0)
    g = np.random.default_rng(1)
    rnn = RecurrentPolicy(RecurrentConfig(cell, 1, 5, 5, n_layers=layers, hidden=hidden, hierarchical=hierarchical))
    opt = Adam(rnn.parameters(), 1e-3)
    for _ in range(10):
        lengths = g.integers(4, T + 1, B)
        mask = torch.from_numpy(np.arange(T)[None, :] < lengths[:, None])
        st = np.stack([g.integers(0, 5, (B, T)), g.integers(0, 5, (B, T)), g.integers(0, 2, (B, T))], -1)
        batch = dict(states=torch.from_numpy(st), prev_actions=torch.from_numpy(g.integers(0, 6, (B, T))),
                     actions=torch.from_numpy(g.integers(0, 5, (B, T))), mask=mask)
        if hierarchical:
            batch["subgoals"] = torch.from_numpy(g.integers(0, 3, (B, T)))
        loss = rnn.loss(batch)
        opt.zero_grad()
        loss.backward()
        opt.step()
        rnn_steps += 1
    rnns.append(rnn)
rnn_ms = (time.perf_counter() - t) / rnn_steps * 1000

def gmacs(product, n=300):  # one (100 x 128) . (128 x 512) product, one thread: a DT layer acting for 100 episodes
    x, w, b = torch.randn(100, 128), torch.randn(512, 128), torch.randn(512)
    product(x, w, b)
    t = time.perf_counter()
    for _ in range(n):
        product(x, w, b)
    return n * 100 * 128 * 512 / (time.perf_counter() - t) / 1e9

threads = torch.get_num_threads()
torch.set_num_threads(1)
with torch.no_grad():
    torch_gmacs, ours_gmacs = gmacs(torch.nn.functional.linear), gmacs(linear)
print(f"{torch.backends.cpu.get_cpu_capability():<7} {threads:>2}  {digest(dt)} {dt_ms:6.0f} ms/step"
      f"  {digest(oc)} {oc_s:5.1f} s  {digest(*rnns)} {rnn_ms:4.0f} ms/step  {torch_gmacs:5.1f} {ours_gmacs:5.1f}")
"""

CONFIGS = [
    ("native (this CPU's best kernels, torch's default threads)", {}),
    ("ATEN_CPU_CAPABILITY=avx2", {"ATEN_CPU_CAPABILITY": "avx2"}),
    ("DNNL_MAX_CPU_ISA=AVX2", {"DNNL_MAX_CPU_ISA": "AVX2"}),
    ("MKL_CBWR=AUTO (MKL's reproducible mode, ISA still chosen per CPU)", {"MKL_CBWR": "AUTO"}),
    ("MKL_CBWR=COMPATIBLE", {"MKL_CBWR": "COMPATIBLE"}),
    ("OPENBLAS_CORETYPE=Haswell (NumPy's BLAS: the networks' products)", {"OPENBLAS_CORETYPE": "Haswell"}),
    ("OMP_NUM_THREADS=1", {"OMP_NUM_THREADS": "1"}),
    ("pinned (hnsdt/core/reproducible.py)", PINNED_CPU),
    ("pinned, second process", PINNED_CPU),
]


# What the pinned rows printed where the committed lock was made: another CPU that prints other hashes at the same
# code computes other bytes (docs/reproducibility.md). A change to the networks' numerics changes them too.
REFERENCE = ("c53af9d0c15a", "918578685691", "3fc61dcd07ff",
             "DT and option-critic: Intel Xeon family 6 model 167, AVX-512, at 71bfd73, and AMD EPYC family 26 model 2 "
             "(Zen 5) at 42ad7b0; RNNs: that Zen 5, measured from 2026-12-03")


def main() -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()  # --help, and nothing else
    pinned: set[tuple[str, str]] = set()
    base = {k: v for k, v in os.environ.items() if k not in PINNED_CPU}
    base.update(ALWAYS)
    print(f"{'configuration':<68} {'ISA':<7} {'th':>2}  {'DT weights':<12} {'DT step':>14}  "
          f"{'OC weights':<12} {'OC 6k':>7}  {'RNN weights':<12} {'RNN step':>12}  {'GMAC/s: torch':>13} {'ours':>5}")
    for name, extra in CONFIGS:
        out = subprocess.run([sys.executable, "-c", CHILD], env={**base, **extra}, capture_output=True, text=True)
        line = out.stdout.strip() or f"failed: {out.stderr.strip().splitlines()[-1:]}"
        print(f"{name:<68} {line}", flush=True)
        if extra is PINNED_CPU and not out.returncode:
            pinned.add(tuple(line.split()[i] for i in (2, 5, 8)))
    ref_dt, ref_oc, ref_rnn, where = REFERENCE
    same = pinned == {(ref_dt, ref_oc, ref_rnn)}
    print(f"\npinned weights {'match' if same else 'DIFFER from'} the reference (DT {ref_dt}, option-critic {ref_oc}, "
          f"RNNs {ref_rnn}: {where}){'' if same else ': this CPU computes other bytes, or the code changed them (then update it)'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
