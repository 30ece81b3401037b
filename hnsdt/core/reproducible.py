"""Same seed, same bytes — on one machine, and across x86-64 machines as far as measured (docs/reproducibility.md
says which machines gave which bytes; MKL and oneDNN, whose results follow the CPU's vendor, now compute only the
LSTM and GRU baselines' training).

Seeding fixes the random streams; the numerics still depend on which kernels the CPU runs. Each of these alone
changes the trained bytes (``benchmarks/cpu_determinism.py`` trains a DT and an option-critic for a few steps and
hashes the weights), so each is pinned for every process of the pipeline and the tests:

* ``ATEN_CPU_CAPABILITY=avx2`` — torch's own vectorised kernels (layer norm, softmax, reductions) otherwise
  pick AVX-512 where the CPU has it and AVX2 where it does not;
* ``MKL_CBWR=COMPATIBLE`` — MKL's conditional numerical reproducibility. MKL dispatches its GEMMs and vector
  maths (torch's CPU ``erf``, ``exp``, ``tanh``, ``sqrt``) by vendor and ISA; per Intel's documentation only
  ``COMPATIBLE`` (SSE2 without approximate reciprocals) gives the same results on Intel and AMD processors alike
  (``AVX2`` is silently ignored on AMD) — not so in our runs, so only the LSTM and GRU still compute there;
* ``DNNL_MAX_CPU_ISA=AVX2`` — oneDNN's JIT kernels (convolutions) likewise;
* ``OPENBLAS_CORETYPE=Haswell`` — NumPy's OpenBLAS, which computes the decision transformers' and Q-networks'
  products (:mod:`hnsdt.models.kernels`: about 2× MKL's ``COMPATIBLE`` code's throughput), picks its kernels by
  core type, not vendor: pinned to its AVX2/FMA kernels, which every machine of this project has (on one thread,
  always: :data:`ALWAYS`);
* ``OMP_NUM_THREADS=2`` — parallel reductions split work by thread count: the machines of this project have 2
  cores, so 2 threads is also torch's default here;
* ``PYTHONHASHSEED=0`` — lerobot orders task lists through Python sets, whose order follows the string hash.

The price is some speed (``benchmarks/cpu_determinism.py`` measures it; docs/reproducibility.md has the figures).
``HNSDT_CPU=native`` skips the pinning (:data:`ALWAYS` excepted) for speed, at the cost of results that depend on
the CPU that made them.
"""

from __future__ import annotations

import os
import sys

# Set whatever the kernels: lerobot's set order, and one BLAS thread (OpenBLAS's own thread pool beside torch's
# threads only contends for the same cores: benchmarks/cpu_determinism.py, docs/reproducibility.md).
ALWAYS = {"PYTHONHASHSEED": "0", "OPENBLAS_NUM_THREADS": "1"}

PINNED_CPU = {
    "ATEN_CPU_CAPABILITY": "avx2",
    "MKL_CBWR": "COMPATIBLE",
    "DNNL_MAX_CPU_ISA": "AVX2",
    "OPENBLAS_CORETYPE": "Haswell",
    "OMP_NUM_THREADS": "2",
}


def pinned_environment() -> dict[str, str]:
    """The variables this process should run under (``HNSDT_CPU=native`` keeps only :data:`ALWAYS`)."""
    env = dict(ALWAYS)
    if os.environ.get("HNSDT_CPU", "pinned") != "native":
        env.update(PINNED_CPU)
    return env


def pin_environment() -> None:
    """Set the pinned variables in ``os.environ`` of a process that has not imported numpy or torch yet (the
    tests); the hash seed only takes effect in child processes."""
    if "torch" in sys.modules or "numpy" in sys.modules:
        raise RuntimeError("pin_environment() must run before numpy and torch are imported")
    os.environ.update(pinned_environment())


def pin_process() -> None:
    """Re-run this process once under the pinned variables, before any heavy import (the stage scripts and
    the ``hnsdt`` command). The hash seed cannot change inside a running interpreter, hence the re-exec."""
    wanted = pinned_environment()
    if any(os.environ.get(k) != v for k, v in wanted.items()):
        os.environ.update(wanted)
        os.execv(sys.executable, [sys.executable, *sys.argv])
