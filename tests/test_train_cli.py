"""Same seed, same bytes, however the runs are grouped and wherever they execute: one process or a pool of
workers, alone or beside other seeds, the local executor, a real (local) Ray instance or a two-node Ray cluster
started by hand."""

import shutil
from pathlib import Path

import pytest

from test_bad_input import hnsdt, workdir  # noqa: F401  (the module fixture: small params and a dataset)


def test_a_seed_trains_to_the_same_bytes_alone_or_after_another(workdir, tmp_path):  # noqa: F811
    common = ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet", "--dataset",
              workdir / "data/datasets/keydoor"]
    together = hnsdt(*common, "--seed", "0", "1", "--workers", "1", "--out", tmp_path / "together", "--curves",
                     tmp_path / "c1", cwd=workdir)
    alone = hnsdt(*common, "--seed", "1", "--out", tmp_path / "alone", "--curves", tmp_path / "c2", cwd=workdir)
    assert together.returncode == 0 and alone.returncode == 0, together.stderr + alone.stderr
    assert sorted(p.name for p in (tmp_path / "together").iterdir()) == ["seed0", "seed1"]
    weights = [(tmp_path / d / "seed1/model.safetensors").read_bytes() for d in ("together", "alone")]
    assert weights[0] == weights[1]
    assert (tmp_path / "c1/seed1.csv").read_text() == (tmp_path / "c2/seed1.csv").read_text()
    assert (tmp_path / "together/seed0/model.safetensors").read_bytes() != weights[0]  # seeds do differ


def _files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_executors_and_worker_counts_give_the_same_bytes(workdir, tmp_path):  # noqa: F811
    """Training (two seeds) and evaluation, each run in this process, by two local workers and on a local
    Ray instance: every checkpoint, curve and results table is identical."""
    train = ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet", "--seed", "0", "1",
             "--dataset", workdir / "data/datasets/keydoor"]
    evaluate = ["evaluate", "--models", workdir / "models", "--quiet"]
    runs = {"inline": ["--workers", "1"], "pool": ["--workers", "2"], "ray": ["--executor", "ray"]}
    for name, how in runs.items():
        for args in ([*train, "--out", tmp_path / name / "models", "--curves", tmp_path / name / "curves"],
                     [*evaluate, "--out", tmp_path / name / "results", "--recordings", tmp_path / name / "rec"]):
            out = hnsdt(*args, *how, cwd=workdir)
            assert out.returncode == 0, f"{name}: {out.stderr[-3000:]}"
    reference = {sub: _files(tmp_path / "inline" / sub) for sub in ("models", "curves", "results")}
    assert len(reference["models"]) == 4 and "metrics.json" in reference["results"]
    for name in ("pool", "ray"):
        for sub in ("models", "curves", "results"):
            assert _files(tmp_path / name / sub) == reference[sub], f"{name} {sub} differ from one process"


@pytest.mark.slow
def test_a_training_killed_after_a_seed_finished_trains_only_the_others_again(workdir, tmp_path):  # noqa: F811
    """`hnsdt train` of two seeds in one process, SIGKILLed once the first has finished (its result kept beside
    the output) and before the output is written, then run again: it says it takes the finished seed, trains
    only the other, and writes the bytes of a run never killed; nothing is left beside the output. Fails when
    nothing is kept (the message is missing) or a kept seed is taken for another."""
    import os
    import signal
    import subprocess
    import sys
    import time

    def command(name):
        return [sys.executable, "-m", "hnsdt.cli", "train", "--env", "keydoor", "--method", "hnsdt", "--quiet",
                "--seed", "0", "1", "--workers", "1", "--dataset", str(workdir / "data/datasets/keydoor"),
                "--out", str(tmp_path / name), "--curves", str(tmp_path / f"{name}-curves")]

    reference = subprocess.run(command("reference"), cwd=workdir, capture_output=True, text=True)
    assert reference.returncode == 0, reference.stderr[-2000:]
    keep = tmp_path / ".hnsdt-tmp-killed-finished"
    proc = subprocess.Popen(command("killed"), cwd=workdir, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    while not list(keep.glob("*.pkl")):
        assert proc.poll() is None, "the training ended before its first seed was kept"
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (tmp_path / "killed").exists(), "the second seed finished before the kill: no test"
    again = subprocess.run(command("killed"), cwd=workdir, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "1 of 2 runs finished before this one was stopped" in again.stdout
    for sub in ("killed", "killed-curves"):
        assert _files(tmp_path / sub) == _files(tmp_path / sub.replace("killed", "reference"))
    assert not keep.exists()


def _plain_environment() -> dict[str, str]:
    """This process's environment less every variable the pipeline pins: what a shell that starts a Ray node
    by hand has."""
    from hnsdt.core.reproducible import ALWAYS, PINNED_CPU

    from tiny_repo import ENV

    return {k: v for k, v in ENV.items() if k not in ALWAYS and k not in PINNED_CPU}


def _kill_processes_naming(text: str) -> None:
    """SIGKILL every process whose command line names ``text`` (a cluster's own temp folder) and their
    descendants (Ray's agents rename themselves): `ray stop` would stop every Ray instance of this user, the
    other test worker's too."""
    import os
    import signal

    parents, named = {}, set()
    for pid in (int(p) for p in os.listdir("/proc") if p.isdigit()):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            parents[pid] = int(stat[stat.rindex(")") + 2:].split()[1])
            if text in Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace"):
                named.add(pid)
        except (OSError, ValueError):
            continue
    doomed, grown = set(named) - {os.getpid()}, True
    while grown:
        more = {pid for pid, parent in parents.items() if parent in doomed} - doomed - {os.getpid()}
        doomed, grown = doomed | more, bool(more)
    for pid in doomed:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


@pytest.mark.slow
def test_a_ray_cluster_started_by_hand_gives_the_local_bytes(workdir, tmp_path):  # noqa: F811
    """A head and a second node started with `ray start` from a plain shell (none of the pinned variables), as
    docs/reproducibility.md shows; `hnsdt train` and `hnsdt evaluate --executor ray` on it, as fresh processes
    with RAY_ADDRESS set, write the bytes of the local executor's run."""
    import socket
    import subprocess
    import tempfile

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    temp = Path(tempfile.mkdtemp(prefix="hnsdt-ray-", dir="/tmp"))  # (Ray's socket paths must stay short)
    plain = _plain_environment() | {"RAY_AUTH_MODE": "token"}  # (Ray 2.60: a joining node and a driver
    # need it to present the token the head wrote to ~/.ray)
    head = ["ray", "start", "--head", "--num-cpus", "1", "--port", str(port), "--temp-dir", str(temp),
            "--include-dashboard", "false", "--disable-usage-stats"]
    node = ["ray", "start", "--address", f"127.0.0.1:{port}", "--num-cpus", "1", "--disable-usage-stats"]
    train = ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet", "--seed", "0", "1",
             "--dataset", workdir / "data/datasets/keydoor"]
    evaluate = ["evaluate", "--models", workdir / "models", "--quiet"]
    try:
        for command in (head, node):
            out = subprocess.run(command, env=plain, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
        for name, how, env in (("local", ["--workers", "1"], None),
                               ("cluster", ["--executor", "ray"], plain | {"RAY_ADDRESS": f"127.0.0.1:{port}"})):
            for args in ([*train, "--out", tmp_path / name / "models", "--curves", tmp_path / name / "curves"],
                         [*evaluate, "--out", tmp_path / name / "results", "--recordings", tmp_path / name / "rec"]):
                if env is None:
                    out = hnsdt(*args, *how, cwd=workdir)
                else:  # a fresh `hnsdt` process, as a user's shell starts it
                    out = subprocess.run(["hnsdt", *map(str, args), *how], cwd=workdir, env=env,
                                         capture_output=True, text=True, timeout=600)
                assert out.returncode == 0, f"{name}: {out.stderr[-3000:]}"
    finally:
        _kill_processes_naming(str(temp))
        shutil.rmtree(temp, ignore_errors=True)
    for sub in ("models", "curves", "results"):
        assert _files(tmp_path / "cluster" / sub) == _files(tmp_path / "local" / sub), f"{sub} differ on the cluster"
