import atexit
import os
import shutil
import sys
import tempfile

# pytest rewrites each test module's asserts on import and caches the result beside it (tests/__pycache__, which
# git ignores), unless bytecode is not to be written (PYTHONDONTWRITEBYTECODE, set on some machines of this
# kind): then every worker rewrites every module, every run — 2-4 s of each `make test-fast`. Cache it anyway.
sys.dont_write_bytecode = False

# Nothing may reach a model/dataset hub from the tests: a private, empty HF home (removed when the test process
# ends: every pytest-xdist worker has its own) and offline mode.
os.environ["HF_HOME"] = tempfile.mkdtemp(prefix="hnsdt-hf-home-")
atexit.register(shutil.rmtree, os.environ["HF_HOME"], ignore_errors=True)
os.environ["HF_HUB_OFFLINE"] = "1"
os.environ.setdefault("MPLBACKEND", "Agg")

# The CPU kernels and thread count the pipeline pins (hnsdt/core/reproducible.py), so learned models and the tests'
# thresholds come out the same on any machine; subprocesses inherit them. Set before NumPy loads (its OpenBLAS
# reads its core type then), and importing the hnsdt package loads NumPy: the module is read from its file.
import importlib.util  # noqa: E402

_spec = importlib.util.spec_from_file_location(
    "_hnsdt_reproducible", os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                        "hnsdt", "core", "reproducible.py"))
_reproducible = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_reproducible)
_reproducible.pin_environment()
# One torch thread per test process, as the pipeline's runs use (compute.threads: 1): pytest-xdist runs one
# test process per core instead. Idle OpenMP threads of the subprocesses sleep rather than spin, so processes
# sharing the cores do not slow each other down (results do not depend on either setting's waiting policy).
os.environ["OMP_NUM_THREADS"] = "1"
os.environ["OMP_WAIT_POLICY"] = "PASSIVE"

import contextlib  # noqa: E402
import io  # noqa: E402
import subprocess  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import hnsdt  # noqa: E402,F401  (registers the environments)
from hnsdt.envs import load_layout  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


AFTER_THE_PIPELINE_RUN = {"test_pipeline_resume.py", "test_pipeline_use.py"}  # files that copy the shared tiny pipeline run (below)
# the end-to-end files whose tests build on each other's repo run whole on one worker, in order: the worker that
# runs the tiny pipeline (test_pipeline.py) resumes it too. test_pipeline_use.py's tests do not depend on each
# other's changes (each worker copies the run for itself): they go to whichever worker is free, so that neither
# worker ends alone on both
END_TO_END = {"test_pipeline.py": "tiny pipeline", "test_pipeline_resume.py": "tiny pipeline"}


def pytest_xdist_make_scheduler(config, log):
    """How pytest-xdist hands out tests: one at a time to whichever worker is free (the fast tier splits evenly
    over two workers), the end-to-end files as END_TO_END says (while one worker runs the tiny pipeline, the
    other runs everything else). xdist's own `--dist loadgroup` would say this with marks, but with pytest 9 it
    groups nothing (it renames tests through an attribute pytest no longer reads), so the scheduler is told here."""
    from xdist.scheduler import LoadScopeScheduling

    class OneTestOrEndToEndFiles(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return END_TO_END.get(os.path.basename(nodeid.split("::", 1)[0]), nodeid)

        def _reschedule(self, node) -> None:
            # xdist tops a worker up once it has 2 tests or fewer left, so near the end a busy worker holds tests
            # the idle one could run; here a worker holds the test it runs and the next (which it needs to know
            # before it runs one: fixture teardown), no more
            if node.shutting_down:
                return
            if not self.workqueue:
                node.shutdown()
            elif self._pending_of(self.assigned_work[node]) <= 1:
                self._assign_work_unit(node)

    return OneTestOrEndToEndFiles(config, log)


def pytest_collection_modifyitems(items):
    """The order the workers are handed tests in (pytest_xdist_make_scheduler above; `--no-loadscope-reorder`):
    the longest first — the slow (end-to-end) tests, then the learning tests, then the files that copy
    the tiny pipeline's run (by then the worker running test_pipeline.py has about finished it) — so that the
    short ones fill the gaps at the end."""
    def rank(item) -> int:
        if item.path.name in AFTER_THE_PIPELINE_RUN:
            return 2
        return 0 if item.get_closest_marker("slow") else 1 if item.get_closest_marker("learning") else 3

    items.sort(key=rank)  # stable


@pytest.fixture(scope="session")
def pipeline_run(tmp_path_factory):
    """The tiny pipeline's first `dvc repro`, shared by every worker (tiny_repo.shared_first_run): its repo, log
    and output md5s."""
    from tiny_repo import shared_first_run

    base = tmp_path_factory.getbasetemp()
    return shared_first_run(base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base)


@pytest.fixture(scope="module")
def repo_copy(pipeline_run, tmp_path_factory, request):
    """The test file's own copy of the tiny pipeline's first run, which its tests may change."""
    from tiny_repo import copy_run

    return copy_run(pipeline_run[0], tmp_path_factory.mktemp(request.module.__name__) / "repo")


@pytest.fixture(scope="module")
def first_run(pipeline_run):
    """The first run's log (with every process's imports) and the md5 of every output in dvc.lock."""
    return pipeline_run[1], pipeline_run[2]


@pytest.fixture(scope="session")
def keydoor():
    return load_layout("keydoor_5x5")


@pytest.fixture(scope="session")
def multikeydoor():
    return load_layout("multikeydoor_9x9")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def hnsdt_cli(*args, cwd=REPO) -> subprocess.CompletedProcess:
    """``hnsdt ARGS`` run in this process from ``cwd`` (``hnsdt.cli.main``, the command's whole body but the
    ``sys.exit``), its exit status and output as a subprocess's would be. A fresh process pays seconds to import
    torch and lerobot; test_cli.py keeps real subprocesses for the entry point itself."""
    from hnsdt.cli import main

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.chdir(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse's usage errors and --help
            code = e.code if isinstance(e.code, int) else 2
    return subprocess.CompletedProcess(["hnsdt", *argv], code, out.getvalue(), err.getvalue())
