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


TINY_PIPELINE = "test_pipeline.py"  # runs the tiny pipeline's first `dvc repro` (its first test's fixture)
AFTER_THE_PIPELINE_RUN = {"test_pipeline_resume.py", "test_pipeline_use.py",  # files that copy that run (below)
                          "test_pipeline_concurrent.py"}
# test_pipeline.py's tests build on each other's repo: they run whole on one worker, in order. The other files
# that need the run copy it for themselves (each test file its own copy): their tests go to whichever worker is
# free once the run is there, so that neither worker ends alone on them
END_TO_END = {TINY_PIPELINE: "tiny pipeline"}


def _file(nodeid: str) -> str:
    return os.path.basename(nodeid.split("::", 1)[0])


def _first_run_done(shared) -> bool:
    """Whether the tiny pipeline's shared first run has ended (tiny_repo.shared_first_run's record of it)."""
    return (shared / "first-run.json").is_file()


def pytest_xdist_make_scheduler(config, log):
    """How pytest-xdist hands out tests: one at a time to whichever worker is free (the fast tier splits evenly
    over two workers), test_pipeline.py whole and first (while one worker runs the tiny pipeline, the other runs
    everything else), and a test that copies that run only once it has ended and to a worker that holds no other
    such test, as long as any other is left (it would wait for the run: 45 s of a worker's time at 16fb3b8; the
    two longest back to back on one worker: a 64-s tail). xdist's own `--dist loadgroup` would say the grouping
    with marks, but with pytest 9 it groups nothing (it renames tests through an attribute pytest no longer
    reads), so the scheduler is told here."""
    from xdist.scheduler import LoadScopeScheduling

    shared = config._tmp_path_factory.getbasetemp()  # (each worker's basetemp is a folder in it: pipeline_run)

    class OneTestOrEndToEndFiles(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return END_TO_END.get(_file(nodeid), nodeid)

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

        def _assign_work_unit(self, node) -> None:
            # a test that copies the tiny pipeline's run waits for it to end, and a worker that already holds one
            # (its next test is handed out while it runs one) would run two of the longest in a row: then the
            # first test in the queue that does neither, if any is left
            held = any(_file(scope) in AFTER_THE_PIPELINE_RUN and not all(unit.values())
                       for scope, unit in self.assigned_work.get(node, {}).items())
            if held or not _first_run_done(shared):
                ready = next((s for s in self.workqueue if _file(s) not in AFTER_THE_PIPELINE_RUN), None)
                if ready is not None:
                    self.workqueue.move_to_end(ready, last=False)
            super()._assign_work_unit(node)

    return OneTestOrEndToEndFiles(config, log)


def pytest_collection_modifyitems(items):
    """The order the workers are handed tests in (pytest_xdist_make_scheduler above; `--no-loadscope-reorder`):
    the longest first — the tiny pipeline's run, the other slow (end-to-end) tests, then the learning tests,
    then the files that copy the tiny pipeline's run (handed out once it has ended) — so that the short ones fill
    the gaps at the end."""
    def rank(item) -> int:
        if item.path.name == TINY_PIPELINE:
            return -1
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
