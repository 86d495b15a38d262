"""Sweeps on a Dask cluster that loses workers (issue 39).

Reference: the same sweep undisturbed, in this process without Dask (workers = 0): its runs
table byte for byte but the seconds column (how long each run took), its summary table and its
worst and first-failed parameter files byte for byte.

Every test starts a real ``dask scheduler`` and ``dask worker`` processes on 127.0.0.1 (one
thread each, no nanny, as tests/test_harness_sweep.py starts them), each worker in a process
group of its own, and kills a worker with SIGKILL of its group at a moment the test chooses by
an event, not by a delay: the sweep's own moments (``harness.sweep.dispatch._hook``, called in this
process, the client) or a function of ``harness.sweep.worker`` that a preloaded module makes
block in the worker to be killed (``BLOCKING``: it writes a file when it is called and never
returns, so the worker is killed while it is inside it).
"""
import csv
import io
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from harness import sweep  # noqa: E402
from harness.scenarios import load_scenarios  # noqa: E402
from harness.sweep import dispatch as sweep_run  # noqa: E402

from conftest import NEAR_LIMITS, NEAR_LIMITS_NAME  # noqa: E402

# two scenarios whose runs are ok, stopped, clipped or refused (each not-ok run runs again on its
# own), so every kind of row is compared
SCENARIOS = ["mismatch_5hz", NEAR_LIMITS_NAME]
SPREADS = ["pi.weights=60%", "tf.poles=0.01", "tf.zero=0.01", "sensor.seed"]
N_RUNS = 60
SEED = 11
CHUNK = 6                       # 20 tasks

BLOCKING = '''"""Preloaded (dask worker --preload) by a worker a test kills: the call number
BLOCK_AFTER + 1 of harness.sweep.worker's function BLOCK_IN writes BLOCK_SIGNAL and never
returns. (Dask loads a preload file more than once, reloading it in the same namespace: the
real function is kept where a reload does not replace it.)"""
import os
import time
from pathlib import Path

from harness.sweep import worker as _worker

_name = os.environ["BLOCK_IN"]
if not hasattr(_worker, "_unblocked_" + _name):
    setattr(_worker, "_unblocked_" + _name, getattr(_worker, _name))
_real = getattr(_worker, "_unblocked_" + _name)
_calls = [0]


def _blocking(*args, **kwargs):
    _calls[0] += 1
    if _calls[0] > int(os.environ.get("BLOCK_AFTER", "0")):
        signal = Path(os.environ["BLOCK_SIGNAL"])
        signal.with_suffix(".tmp").write_text(str(os.getpid()))
        signal.with_suffix(".tmp").rename(signal)
        while True:
            time.sleep(0.5)
    return _real(*args, **kwargs)


setattr(_worker, _name, _blocking)
'''


def _env():
    return {**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1"}


def _free_port():
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _killpg(proc):
    """SIGKILL of the process's group; wait for it to be gone."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


class Cluster:
    """A `dask scheduler` and named `dask worker` processes on 127.0.0.1."""

    def __init__(self, folder):
        self.dask = shutil.which("dask")
        assert self.dask, "the dask command line is needed (pip install 'dask[distributed]')"
        self.folder = Path(folder)
        self.address = f"tcp://127.0.0.1:{_free_port()}"
        self.workers = {}
        self.scheduler = subprocess.Popen(
            [self.dask, "scheduler", "--host", "127.0.0.1", "--port", self.address.rsplit(":", 1)[1],
             "--no-dashboard"], env=_env(), cwd=self.folder, stdout=subprocess.DEVNULL,
            stderr=open(self.folder / "scheduler.log", "w"), start_new_session=True)

    def start(self, name, block_in=None, block_after=0, wait=True):
        """Start worker ``name``; with ``block_in``, its call number ``block_after`` + 1 of that
        function blocks (the file ``signal_of(name)`` then exists)."""
        env = _env()
        cmd = [self.dask, "worker", self.address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
               "--host", "127.0.0.1", "--name", name]
        if block_in:
            preload = self.folder / "blocking.py"
            preload.write_text(BLOCKING)
            env.update(BLOCK_IN=block_in, BLOCK_AFTER=str(block_after), BLOCK_SIGNAL=str(self.signal_of(name)))
            cmd += ["--preload", str(preload)]
        self.workers[name] = subprocess.Popen(cmd, env=env, cwd=self.folder, stdout=subprocess.DEVNULL,
                                              stderr=open(self.folder / f"{name}.log", "w"),
                                              start_new_session=True)
        if wait:
            self.wait_for(name)

    def signal_of(self, name):
        return self.folder / f"{name}.blocked"

    def names(self, client=None):
        """Address -> name of the workers the scheduler has (asked through ``client``, else
        a client of its own)."""
        from dask.distributed import Client
        if client is not None:
            return {a: w["name"] for a, w in client.scheduler_info(n_workers=-1)["workers"].items()}
        with Client(self.address, timeout=60) as own:
            return self.names(own)

    def wait_for(self, *names, timeout=120):
        deadline = time.time() + timeout
        while time.time() < deadline:
            if set(names) <= set(self.names().values()):
                return
            for name in names:
                assert self.workers[name].poll() is None, (self.folder / f"{name}.log").read_text()
            time.sleep(0.1)
        raise AssertionError(f"workers {names} did not register")

    def kill(self, name):
        _killpg(self.workers[name])

    def kill_when_blocked(self, name, then=None):
        """A thread that kills ``name`` once it is blocked (its signal file exists), after
        calling ``then`` (e.g. start another worker)."""
        def watch():
            while not self.signal_of(name).exists():
                if self.workers[name].poll() is not None:
                    return
                time.sleep(0.02)
            if then is not None:
                then()
            self.kill(name)

        thread = threading.Thread(target=watch, daemon=True)
        thread.start()
        return thread

    def close(self):
        for proc in [*self.workers.values(), self.scheduler]:
            if proc.poll() is None:
                _killpg(proc)


@pytest.fixture
def cluster(tmp_path):
    c = Cluster(tmp_path)
    yield c
    c.close()


def _sweep(**kwargs):
    return sweep.run_sweep(SCENARIOS, SPREADS, N_RUNS, seed=SEED, chunk=CHUNK,
                           registry=load_scenarios([NEAR_LIMITS]), **kwargs)


def _without_seconds(data):
    """A runs table's bytes without its seconds column (the sixth; the reason, which may hold
    commas, is the last)."""
    out = []
    for line in data.splitlines(keepends=True):
        cells = line.split(b",", 6)
        out.append(b",".join(cells[:5] + cells[6:]))
    return b"".join(out)


def _written(folder):
    """The outputs as compared: {file name: bytes}, the runs table without its seconds."""
    files = {}
    for path in sorted(Path(folder).iterdir()):
        if path.name == sweep.RUNS:
            files[path.name] = _without_seconds(path.read_bytes())
        elif path.name == "sweep_summary.csv" or path.suffix == ".toml":
            files[path.name] = path.read_bytes()
    return files


def _files(result, folder):
    """Write the sweep's outputs to ``folder``; :func:`_written`."""
    sweep.write_outputs(result, folder, plots=False)
    return _written(folder)


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("undisturbed")
    result = _sweep(workers=0)
    files = _files(result, folder)
    counts = {name: result.counts(name) for name in SCENARIOS}
    # the comparison means something: every kind of row is there
    assert counts["mismatch_5hz"]["ok"], counts
    near = counts[NEAR_LIMITS_NAME]
    assert near["ok"] and near["stopped"] and near["saturated"] and near["invalid"], counts
    assert {"sweep_runs.csv", "sweep_summary.csv", f"worst_{NEAR_LIMITS_NAME}.toml",
            f"failed_{NEAR_LIMITS_NAME}.toml", "worst_mismatch_5hz.toml"} <= set(files)
    return files


def _sweep_killing_when_blocked(cluster, folder, name, then=None):
    """The sweep on ``cluster``, worker ``name`` killed once it is blocked (after ``then``);
    the result, the worker checked to have been killed there."""
    killer = cluster.kill_when_blocked(name, then=then)
    result = _sweep(scheduler=cluster.address, out=folder)
    killer.join(timeout=60)
    assert cluster.signal_of(name).exists() and cluster.workers[name].poll() is not None
    return result


def _kill_the_only_holder(cluster, client, future):
    """Kill the worker that holds the only copy of ``future``'s result, once there is one
    copy (Dask's active memory manager drops the copies a broadcast made within seconds);
    return its name."""
    from dask.distributed import wait

    wait(future, timeout=60)
    deadline = time.time() + 60
    while len(holders := client.who_has(future)[future.key]) != 1:
        assert time.time() < deadline, holders
        time.sleep(0.1)
    name = cluster.names(client)[holders[0]]
    cluster.kill(name)
    return name


def _check_same(result, folder, undisturbed):
    assert _files(result, folder) == undisturbed
    assert all(len(result.runs[name]) == N_RUNS for name in SCENARIOS)


class Stream(io.StringIO):
    """A progress stream that sets an event when a line holds ``text``."""

    def __init__(self, text=None):
        super().__init__()
        self.text, self.seen = text, threading.Event()

    def write(self, s):
        if self.text and self.text in s:
            self.seen.set()
        return super().write(s)


def _hooked(monkeypatch, moments):
    """At the sweep's moment ``name`` run ``moments[name](**details)`` once, the first time;
    ``moments[name] = (k, f)``: the k-th time."""
    done, seen = set(), {}

    def hook(name, **details):
        seen[name] = seen.get(name, 0) + 1
        k, fn = moments[name] if isinstance(moments.get(name), tuple) else (1, moments.get(name))
        if fn is not None and seen[name] == k:
            done.add(name)
            fn(**details)

    monkeypatch.setattr(sweep_run, "_hook", hook)
    return done


def test_worker_lost_before_the_inputs_are_sent(cluster, tmp_path, undisturbed, monkeypatch):
    """A worker killed once the client is connected, before it sends the sweep's inputs (the
    scheduler may not know it is gone yet): the sweep completes on the other, the same."""
    cluster.start("a")
    cluster.start("b")
    done = _hooked(monkeypatch, {"connected": lambda client: cluster.kill("a")})
    result = _sweep(scheduler=cluster.address, out=tmp_path / "out")
    assert done == {"connected"}
    _check_same(result, tmp_path / "out", undisturbed)


def test_worker_lost_while_it_prepares(cluster, tmp_path, undisturbed):
    """A worker killed while it loads the shipped FMUs before the clock starts
    (prepare_worker, run by the client on every worker): the same result."""
    cluster.start("a", block_in="prepare_worker")
    cluster.start("b")
    result = _sweep_killing_when_blocked(cluster, tmp_path / "out", "a")
    _check_same(result, tmp_path / "out", undisturbed)


def test_worker_lost_while_it_computes_the_inputs_and_another_joins(cluster, tmp_path, undisturbed):
    """The only worker is killed while it computes the sweep's inputs (the task every task of
    runs depends on); a worker that joins then, which has not seen them, runs the sweep: the
    same result."""
    cluster.start("a", block_in="sweep_inputs")
    result = _sweep_killing_when_blocked(cluster, tmp_path / "out", "a", then=lambda: cluster.start("b"))
    _check_same(result, tmp_path / "out", undisturbed)


def test_worker_lost_while_it_runs_a_task(cluster, tmp_path, undisturbed):
    """A worker killed while it runs a task of runs (its second): the task is run again
    elsewhere and every run is recorded once, the same."""
    cluster.start("a", block_in="run_chunk", block_after=1)
    cluster.start("b")
    result = _sweep_killing_when_blocked(cluster, tmp_path / "out", "a")
    _check_same(result, tmp_path / "out", undisturbed)


@pytest.mark.parametrize("moment", ["shipped", "completed"], ids=["the-inputs", "a-result"])
def test_worker_holding_the_only_copy_is_lost(cluster, tmp_path, undisturbed, monkeypatch, moment):
    """The worker holding the only copy of some data is killed. the-inputs: the issue's
    failure, what every task needs, once it is there and before any task of runs is handed
    out; scattered with broadcast, the inputs were lost with it (Dask's active memory manager
    keeps one copy) and every task was cancelled ("lost dependencies"). a-result: a task's
    result the client has not gathered yet, which Dask computes again. The sweep completes on
    the other worker, the same."""
    cluster.start("a")
    cluster.start("b")
    killed = []
    _hooked(monkeypatch, {moment: lambda client, future: killed.append(
        _kill_the_only_holder(cluster, client, future))})
    result = _sweep(scheduler=cluster.address, out=tmp_path / "out")
    assert len(killed) == 1
    _check_same(result, tmp_path / "out", undisturbed)


def test_all_workers_lost_then_one_joins(cluster, tmp_path, undisturbed, monkeypatch):
    """Every worker killed mid-sweep: the sweep says that the cluster has no worker and
    waits; a worker that joins then finishes it, the same."""
    cluster.start("a")
    cluster.start("b")
    stream = Stream("no worker on the cluster")

    def kill_all(client, future):
        cluster.kill("a")
        cluster.kill("b")

        def later():
            stream.seen.wait(timeout=120)
            cluster.start("c", wait=False)

        threading.Thread(target=later, daemon=True).start()

    _hooked(monkeypatch, {"completed": kill_all})
    result = _sweep(scheduler=cluster.address, out=tmp_path / "out", progress=stream)
    text = stream.getvalue()
    assert stream.seen.is_set(), text
    assert "waiting up to 600 s for one (--no-workers-timeout)" in text
    assert "1 worker on the cluster again; going on" in text
    _check_same(result, tmp_path / "out", undisturbed)


def test_no_worker_for_too_long_stops_in_one_line_and_resume_completes(cluster, tmp_path, undisturbed,
                                                                        monkeypatch, capsys):
    """Every worker killed mid-sweep and none joining within --no-workers-timeout: the command
    exits 1 with one line that says why and where the runs are; the journal keeps the runs
    done; --resume on workers that join later computes only the others and ends the same."""
    from harness.cli import main

    cluster.start("a")
    cluster.start("b")
    out = tmp_path / "out"
    kept = {}

    def kill_all(client, future):
        cluster.kill("a")
        cluster.kill("b")

    _hooked(monkeypatch, {"completed": (3, kill_all)})             # two tasks' runs recorded
    args = ["sweep", *SCENARIOS, "-n", str(N_RUNS), *[f"--vary={s}" for s in SPREADS], "--seed", str(SEED),
            "--chunk", str(CHUNK), "--scenario-file", str(NEAR_LIMITS), "--no-plots", "--out", str(out),
            "--scheduler", cluster.address]
    assert main([*args, "--no-workers-timeout", "3"]) == 1
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert last.startswith("python -m harness sweep: error: "), err
    assert f"the cluster at {cluster.address} had no worker for 3 s" in last
    assert f"in {out / sweep.JOURNAL}: rerun with --resume" in last
    missing = int(last.split("error: ")[1].split(" of ")[0])
    with open(out / sweep.JOURNAL, newline="") as f:
        for row in list(csv.reader(f))[1:]:
            kept[(row[0], int(row[1]))] = row
    assert len(kept) == 2 * N_RUNS - missing >= 2 * CHUNK
    monkeypatch.setattr(sweep_run, "_hook", None)
    cluster.start("c")
    assert main([*args, "--resume"]) == 0
    text = capsys.readouterr()
    assert f"{len(kept)} of {2 * N_RUNS} runs done, {missing} to compute" in text.err
    with open(out / sweep.RUNS, newline="") as f:
        final = {(row[0], int(row[1])): row for row in list(csv.reader(f))[1:]}
    assert all(final[key] == row for key, row in kept.items())     # not computed again
    assert not (out / sweep.JOURNAL).exists()
    assert _written(out) == undisturbed


def test_killed_client_then_resume_on_the_same_cluster(cluster, tmp_path, undisturbed):
    """The client (`python -m harness sweep --scheduler ...`) killed with its process group
    while its workers hold tasks (each worker's third task blocks, so the journal holds the
    runs of four tasks when it is killed); --resume from another client on fresh workers
    computes only the missing runs, keeps the journal's rows and ends the same."""
    cluster.start("a", block_in="run_chunk", block_after=2)
    cluster.start("b", block_in="run_chunk", block_after=2)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "harness", "sweep", *SCENARIOS, "-n", str(N_RUNS),
           *[f"--vary={s}" for s in SPREADS], "--seed", str(SEED), "--chunk", str(CHUNK),
           "--scenario-file", str(NEAR_LIMITS), "--no-plots", "--out", str(out), "--scheduler", cluster.address]
    first = subprocess.Popen(cmd, env=_env(), cwd=tmp_path, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.time() + 240
        while not (cluster.signal_of("a").exists() and cluster.signal_of("b").exists()):
            assert time.time() < deadline and first.poll() is None, "the workers did not block"
            time.sleep(0.05)
        # both blocked in their third task: the journal has the rows of the four before
        deadline = time.time() + 60
        while (out / sweep.JOURNAL).read_bytes().count(b"\n") - 1 < 4 * CHUNK:
            assert time.time() < deadline, (out / sweep.JOURNAL).read_text()
            time.sleep(0.05)
    finally:
        _killpg(first)
    with open(out / sweep.JOURNAL, newline="") as f:
        kept = {(row[0], int(row[1])): row for row in list(csv.reader(f))[1:]}
    assert len(kept) == 4 * CHUNK
    cluster.kill("a")
    cluster.kill("b")
    cluster.start("c")
    cluster.start("d")
    resumed = subprocess.run([*cmd, "--resume"], env=_env(), cwd=tmp_path, capture_output=True, text=True,
                             timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(kept)} of {2 * N_RUNS} runs done, {2 * N_RUNS - len(kept)} to compute" in resumed.stderr
    with open(out / sweep.RUNS, newline="") as f:
        final = {(row[0], int(row[1])): row for row in list(csv.reader(f))[1:]}
    assert all(final[key] == row for key, row in kept.items())     # not computed again
    assert _written(out) == undisturbed
