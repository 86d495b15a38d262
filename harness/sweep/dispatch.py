"""Running a sweep: the runs handed out to Dask (or run here), collected as they complete."""

from __future__ import annotations

from collections import deque
import hashlib
import logging
import math
import os
from pathlib import Path
import tempfile
import time
import uuid

import numpy as np

from .. import masters
from ..bench.bound import Bound, measure_runner
from ..fmu import (CONTROLLER_MODEL, PLANT_MODEL, FMUError, UnknownParameterError, fmu_path, load,
                   starts_of)
from ..loop import normalize_master, prepare_closed_loop
from ..scenarios import get_scenario
from .manifest import prepare_folder, sweep_identity, write_manifest
from .spreads import Spread, parse_spread, varied_keys, varies_something
from .store import STATUS_CODE, ParameterSets, RunRows, RunStore, SweepResult
from .worker import (first_line, peak_rss, prepare_worker, remove_at_exit, run_chunk, scenario_fields,
                     sweep_inputs)

__all__ = ["run_sweep", "SweepIncompleteError", "plant_start_values"]


class SweepIncompleteError(RuntimeError):
    """Runs are missing after the sweep (their tasks failed on every attempt)."""


def plant_start_values(fmu_dir=None):
    """The PiezoStage parameters' start values from its model description (name -> value),
    the FMU checked to be an FMI 2.0 Co-Simulation FMU."""
    return starts_of(load(fmu_path(PLANT_MODEL, fmu_dir)).md)


#: CPU seconds of the runner per task the chunk size aims at (native backend)
TASK_SECONDS = 0.5
#: runs per task without a measured cost (the fmpy backend), at most
FMPY_CHUNK = 50


def _chunk_sizes(n_runs, n_workers, cost, chunk):
    """(largest runs per task, whether it is fixed): ``chunk`` when given; else about
    :data:`TASK_SECONDS` of the runner's CPU time per task (``cost``: seconds per run), and
    at most a quarter of each worker's share of a scenario's runs."""
    if chunk:
        return int(chunk), True
    share = math.ceil(n_runs / (4 * max(n_workers, 1)))
    if cost:
        return max(1, min(share, round(TASK_SECONDS / cost))), False
    return max(1, min(FMPY_CHUNK, share)), False


def _chunks(store, names, largest, fixed, parallel):
    """The missing runs as tasks ``(name, indices)``, made as they are handed out: nothing the
    size of all the runs is held. Unless fixed, a task shrinks towards the end (at most a
    quarter of each worker's share of the runs still to hand out), so the workers finish
    together."""
    left = sum(store.n - store.done(name) for name in names)

    def size():
        return largest if fixed else max(1, min(largest, math.ceil(left / (4 * max(parallel, 1)))))

    for name in names:
        held = np.empty(0, np.int64)
        for block in store.missing_blocks(name):
            held = np.concatenate((held, block))
            while held.size >= size():
                part, held = held[:size()], held[size():]
                left -= part.size
                yield name, part
        if held.size:
            left -= held.size
            yield name, held


def _compact(indices):
    """A task's runs as sent: a ``range`` when they follow each other (a few bytes, whatever
    their number), else the array."""
    if indices.size and int(indices[-1]) - int(indices[0]) + 1 == indices.size:
        return range(int(indices[0]), int(indices[-1]) + 1)
    return indices


def _nominal_setups(scs, bases, options):
    """Each scenario's experiment with its nominal plant (``bases``) and the sweep's options:
    what the compute bound is measured on."""
    return {sc.name: prepare_closed_loop(sc, plant_params=bases[sc.name], adaptation=options["adaptation"],
                                         preview=options["preview"], master=options["master"])
            for sc in scs}


def _fmu_package(fmu_dir):
    """Content digest and ``{file name: bytes}`` of both FMUs, shipped to every worker."""
    files = {}
    digest = hashlib.sha256()
    for model in (PLANT_MODEL, CONTROLLER_MODEL):
        path = fmu_path(model, fmu_dir)
        data = path.read_bytes()
        files[path.name] = data
        digest.update(data)
    return digest.hexdigest(), files


class _Progress:
    """Progress of the runs on stderr, with the rate and the time left: a rewritten line on
    a terminal, else a line per 10 % of the runs (and at least every 30 s)."""

    def __init__(self, total, done, stream):
        self.total, self.stream = total, stream
        self.done = self.start = done
        self.bad = 0
        self.t0 = self.last = time.perf_counter()
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.next_mark = (math.floor(10 * done / total) + 1) / 10 if total else 1.0

    def update(self, new, bad):
        """``new`` runs recorded, ``bad`` of them not ok."""
        self.done += int(new)
        self.bad += int(bad)
        now = time.perf_counter()
        frac = self.done / self.total
        elapsed = now - self.t0
        rate = (self.done - self.start) / elapsed if elapsed > 0 else 0.0
        eta = f", ETA {(self.total - self.done) / rate:.0f} s" if rate > 0 and self.done < self.total else ""
        text = (f"sweep: {self.done}/{self.total} runs ({frac:.0%}), {self.bad} not ok, "
                f"{elapsed:.1f} s, {rate:.0f} runs/s{eta}")
        if self.tty:
            self.stream.write("\r" + text + ("\n" if self.done == self.total else ""))
            self.stream.flush()
        elif frac >= self.next_mark or self.done == self.total or now - self.last >= 30.0:
            self.stream.write(text + "\n")
            self.stream.flush()
            self.last = now
            while self.next_mark <= frac:
                self.next_mark += 0.1

    def say(self, text):
        self.stream.write(("\n" if self.tty and self.done < self.total else "") + text + "\n")
        self.stream.flush()


#: how long a sweep on Dask waits, by default, with no worker on the cluster before it stops [s]
NO_WORKERS_TIMEOUT = 600.0


def run_sweep(scenarios, spreads, n_runs, *, seed=1, scheduler=None, workers=None, chunk=None,
              backend="native", adaptation=None, preview=True, master="gauss-seidel",
              fmu_dir=None, registry=None, progress=None, out=None, resume=False,
              no_workers_timeout=NO_WORKERS_TIMEOUT):
    """Run a Monte Carlo sweep, streaming every run to disk as its task completes.

    Parameters
    ----------
    scenarios : sequence of str
        Tracking scenarios.
    spreads : sequence of Spread or str
        The distributions (``KEY=SPEC`` strings are parsed); at least one must move a
        parameter.
    n_runs : int
        Runs per scenario.
    seed : int
        Seed of the draws.
    scheduler : str, optional
        Address of an existing Dask scheduler (e.g. ``tcp://10.0.0.5:8786``); else a local
        cluster of ``workers`` processes is started (and stopped) for the sweep.
    workers : int, optional
        Local worker processes (default: the number of cores); 0 runs everything in this
        process without Dask.
    chunk : int, optional
        Runs per task (default: with the native backend about :data:`TASK_SECONDS` of the
        runner's CPU time per task, shrinking towards the end; with fmpy at most
        :data:`FMPY_CHUNK`; either way at most a quarter of each worker's share).
    backend : {"native", "fmpy"}
    adaptation, preview, master
        As :func:`harness.masters.fmpy.simulate_closed_loop`.
    fmu_dir, registry
        FMU folder and scenario registry.
    progress : file, optional
        Where the progress goes (e.g. ``sys.stderr``).
    out : path, optional
        Folder of the journal (``sweep_runs.journal.csv``, one row per run as it completes)
        and the manifest (``sweep_manifest.json``); default: a temporary folder.
    resume : bool
        Continue the unfinished sweep in ``out`` (the same scenarios, runs, seed, spreads,
        options and FMUs): only its missing runs are computed.
    no_workers_timeout : float
        Seconds a sweep on Dask waits with no worker on the cluster (all lost, or none yet)
        before it stops with :class:`SweepIncompleteError`; its runs so far are in the journal.

    Returns
    -------
    SweepResult

    Raises
    ------
    ValueError
        Bad arguments, nothing varied, or ``out`` holding another (or an unfinished) sweep.
    SweepIncompleteError
        Runs whose task failed on every attempt, or the sweep stopped because the cluster had
        no worker for ``no_workers_timeout`` or the scheduler was lost (the others are in the
        journal: resume).
    """
    t_start = time.perf_counter()
    if n_runs < 1:
        raise ValueError(f"the number of runs must be at least 1, got {n_runs}")
    if not no_workers_timeout >= 0:
        raise ValueError(f"the time to wait for workers must be >= 0 s, got {no_workers_timeout}")
    masters.check_sweep_backend(backend)
    master = normalize_master(master)
    base_all = plant_start_values(fmu_dir)
    reals = [k for k, v in base_all.items() if isinstance(v, float)]
    spreads = [s if isinstance(s, Spread) else parse_spread(s, reals) for s in spreads]
    keys = [s.key for s in spreads]
    if len(set(keys)) != len(keys):
        raise ValueError(f"a key is varied twice: {', '.join(keys)}")
    scs = [get_scenario(name, registry) for name in scenarios]
    for sc in scs:
        if sc.kind != "tracking":
            raise ValueError(f"scenario '{sc.name}' is a {sc.kind} scenario; a sweep needs tracking "
                             f"scenarios")
    if not varies_something(spreads):
        what = "no spread is given" if not spreads else "every spread has width 0"
        raise ValueError(f"nothing varies ({what}): all {n_runs} runs would be the same run; add "
                         f"--vary KEY=SPEC, e.g. --vary pi.weights=10% --vary sensor.seed")
    bases = {}
    for sc in scs:
        base = {**base_all, **dict(sc.plant)}
        base.setdefault("h", sc.step_size)
        bases[sc.name] = base
    varied = sorted(set().union(*(varied_keys(spreads, b) for b in bases.values())))
    options = {"backend": backend, "adaptation": adaptation, "preview": bool(preview),
               "master": master}
    package = _fmu_package(fmu_dir)
    identity = sweep_identity(scs, spreads, n_runs, seed, options, package[0], bases)
    names = [sc.name for sc in scs]
    total = n_runs * len(scs)

    if out is None:
        folder = Path(tempfile.mkdtemp(prefix="harness_sweep_runs_"))
        remove_at_exit(folder)
    else:
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
    fresh = prepare_folder(folder, identity, resume, progress)
    store = RunStore(folder, names, n_runs, varied)
    if not fresh:
        store.load()
    write_manifest(folder, identity, complete=False)
    store.open(fresh)
    done_before = store.done()
    if progress is not None and done_before:
        progress.write(f"sweep: resuming {folder}: {done_before} of {total} runs done, "
                       f"{total - done_before} to compute\n")
    prog = _Progress(total, done_before, progress) if progress is not None else None
    inputs = sweep_inputs(package, {sc.name: (scenario_fields(sc), bases[sc.name]) for sc in scs},
                          spreads, varied, options)
    failures = []
    stopped = []
    # the largest worker's peak RSS; the tasks' CPU and wall-clock seconds
    tally = {"worker_rss": None, "task_cpu": 0.0, "task_wall": 0.0}

    def collect(name, result):
        rows, rss, (cpu, wall) = result
        tally["task_cpu"] += cpu
        tally["task_wall"] += wall
        if rss is not None:
            tally["worker_rss"] = max(rss, tally["worker_rss"] or 0)
        new = store.add_rows(name, rows)
        if prog:
            prog.update(np.count_nonzero(new), np.count_nonzero(new & (rows.codes != STATUS_CODE["ok"])))

    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    runner, unbound = None, None
    if backend == "native" and total > done_before:
        if progress is not None:
            progress.write("sweep: timing the native runner on each scenario (the compute bound)\n")
        try:
            runner = measure_runner(_nominal_setups(scs, bases, options), fmu_dir)
        except (FMUError, UnknownParameterError, TypeError, ValueError) as exc:
            # a nominal plant that fails its run: the sweep's runs say what they do; no bound
            unbound = f"the nominal run failed: {first_line(exc)}"
    n_workers = (os.cpu_count() or 1) if workers is None else int(workers)

    def tasks(parallel):
        cost = max(runner[k] * sc.n_samples * 1e-9 for k, sc in zip(names, scs)) if runner else None
        largest, fixed = _chunk_sizes(n_runs, parallel, cost, chunk)
        return _chunks(store, names, largest, fixed, parallel)

    clock = {}
    try:
        if scheduler is None and n_workers == 0:
            where, cores = "this process (no Dask)", 1
            prepare_worker(package, options)
            clock["start"], cpu = time.perf_counter(), time.process_time()
            for name, part in tasks(1):
                rows, _, used = run_chunk(inputs, name, seed, part)
                collect(name, (rows, None, used))
            clock["end"] = time.perf_counter()
            clock["cpu"] = time.process_time() - cpu - tally["task_cpu"]     # this process besides the tasks
        else:
            where, cores = _run_on_dask(scheduler, n_workers, inputs, seed, tasks, collect, failures,
                                        stopped, prog, clock, no_workers_timeout)
    except KeyboardInterrupt:
        store.close()
        if progress is not None:
            progress.write(f"\nsweep: interrupted: {store.done()} of {total} runs are in {store.path}; "
                           f"the same command with --resume computes the rest\n")
            progress.flush()
        raise
    store.close()
    missing = total - store.done()
    if missing and stopped:
        raise SweepIncompleteError(f"{missing} of {total} runs are missing: {stopped[-1]}; the others are "
                                   f"in {store.path}: rerun with --resume")
    if missing:
        why = f" (last error: {failures[-1]})" if failures else ""
        raise SweepIncompleteError(f"{missing} of {total} runs are missing: their tasks failed on every "
                                   f"attempt{why}; the others are in {store.path}: rerun with --resume")
    peak = {"client": peak_rss(), "worker": tally["worker_rss"]}
    bound = (Bound(runner, {sc.name: sc.n_samples for sc in scs}, cores) if runner else None)
    return SweepResult(names, spreads,
                       {sc.name: ParameterSets(bases[sc.name], spreads, seed, n_runs) for sc in scs},
                       {name: RunRows(store, name) for name in names},
                       time.perf_counter() - t_start, where, options, computed=total - done_before,
                       peak_rss=peak, store=store,
                       compute_seconds=clock["end"] - clock["start"] if "end" in clock else math.nan,
                       bound=bound if bound is not None else unbound, load=load,
                       cpu_seconds={"tasks": tally["task_cpu"], "client": clock.get("cpu", math.nan),
                                    "tasks_wall": tally["task_wall"]})


_ATTEMPTS = 4          # a task that fails this many times (its own error, or KilledWorker) leaves its runs missing
_WATCH = 2.0           # seconds between the client's looks at the cluster's workers

#: called as ``_hook(moment, client=..., future=...)`` at the moments of a sweep on Dask:
#: "connected", "shipped" (the inputs submitted, the workers prepared; ``future``: the
#: inputs), "completed" (``future``: a task done, before its result is gathered). None:
#: nothing. The tests kill workers there.
_hook = None


def _moment(name, **details):
    if _hook is not None:
        _hook(name, **details)


class _Stopped(Exception):
    """The sweep cannot go on on this cluster (no worker for too long, the scheduler lost)."""


def _run_on_dask(scheduler, n_workers, inputs, seed, tasks, collect, failures, stopped, prog, clock,
                 no_workers_timeout):
    """Run the missing runs on Dask; return (where, the runs computed at once). At most a few
    tasks per thread of the cluster (as many threads as it has now) are queued at a time, made
    as they are handed out (memory does not grow with the number of runs).

    What every task needs besides its runs (:func:`sweep_inputs`: the FMUs, the scenarios,
    the spreads, the options) is a task of its own that the tasks of runs depend on, so their
    messages stay small; the scheduler computes it again when the workers holding it are
    lost (it is submitted again if it fails). A task lost with its worker is rescheduled by
    Dask; a task that fails anyway is submitted again (:data:`_ATTEMPTS`), a cancelled one
    without counting an attempt. With no worker on the cluster for ``no_workers_timeout``
    seconds, or the scheduler lost for good, the sweep stops (``stopped`` gets why). ``clock``
    gets the start (the first task handed out), the end (the last one collected) and the
    CPU seconds of this process in between (the client, and a local cluster's scheduler)."""
    import dask                                                         # heavy: only here
    from dask.distributed import Client, LocalCluster, TimeoutError as DaskTimeoutError, as_completed
    from distributed.client import FutureCancelledError

    cluster = None
    if scheduler is None:
        # without Dask's statistical profiler, which samples every worker's stack 100 times a
        # second and keeps an hour of it: a worker's memory would grow with the sweep's length
        with dask.config.set({"distributed.worker.profile.enabled": False}):
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
        client = Client(cluster)
        where = f"a local Dask cluster of {n_workers} worker process{'es' if n_workers > 1 else ''}"
        address, known = cluster.scheduler_address, n_workers
        cores = min(n_workers, os.cpu_count() or n_workers)
    else:
        client = Client(scheduler, timeout=30)
        info = client.scheduler_info()
        nw = len(info.get("workers", {}))
        where = f"the Dask cluster at {scheduler} ({nw} worker{'s' if nw != 1 else ''})"
        address, known = scheduler, nw
        n_workers = max(nw, 1)
        cores = max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))
    try:
        _moment("connected", client=client)
        shipped = {}

        def ship():
            """The inputs' task, submitted again when it failed or was cancelled (a lost
            result the scheduler computes again by itself)."""
            fut = shipped.get("inputs")
            if fut is None or fut.status in ("error", "cancelled"):
                fut = client.submit(sweep_inputs, **inputs, key=f"sweep_inputs-{uuid.uuid4().hex}", pure=False)
                shipped["inputs"] = fut
            return fut

        ship()
        # the workers there now load the FMUs before the clock starts (part of the start, like
        # the cluster's); a worker that joins later does it in its first task, and a worker
        # that cannot (or is lost meanwhile) fails its tasks, which are retried and reported
        # as any failed task
        try:
            client.run(prepare_worker, inputs["package"], inputs["options"])
        except Exception:                       # noqa: BLE001 - the tasks meet it again and report it
            pass
        _moment("shipped", client=client, future=shipped["inputs"])
        source = tasks(cores)
        retry = deque()
        inflight = {}
        queue = as_completed()
        # a few tasks queued per thread of the cluster, as many as it has now
        watch = {"next": time.monotonic() + _WATCH, "workers": known, "none_since": None,
                 "limit": max(8, 4 * max(n_workers, cores))}

        def submit():
            if retry:
                name, part, attempt = retry.popleft()
            else:
                nxt = next(source, None)
                if nxt is None:
                    return False
                (name, part), attempt = nxt, 1
            fut = client.submit(run_chunk, ship(), name, seed, _compact(part), pure=False)
            inflight[fut] = (name, part, attempt)
            queue.add(fut)
            return True

        def look():
            """Check the cluster's workers; say when their number changes; raise _Stopped
            when there has been none for too long or the scheduler is lost for good."""
            if client.status == "closed":
                raise _Stopped(f"the connection to the scheduler at {address} was lost")
            try:
                threads = client.nthreads()
            except Exception:                   # noqa: BLE001 - reconnecting: looked at again
                if client.status == "closed":
                    raise _Stopped(f"the connection to the scheduler at {address} was lost") from None
                return
            now = time.monotonic()
            n, before = len(threads), watch["workers"]
            watch["workers"] = n
            watch["limit"] = max(8, 4 * sum(threads.values()))
            if n:
                if watch["none_since"] is not None and prog is not None:
                    prog.say(f"sweep: {n} worker{'s' if n != 1 else ''} on the cluster again; going on")
                elif before is not None and n != before and prog is not None:
                    prog.say(f"sweep: {n} worker{'s' if n != 1 else ''} on the cluster (were {before})")
                watch["none_since"] = None
                return
            if watch["none_since"] is None:
                watch["none_since"] = now
                if prog is not None:
                    prog.say(f"sweep: no worker on the cluster at {address}; waiting up to "
                             f"{no_workers_timeout:.0f} s for one (--no-workers-timeout)")
            if now - watch["none_since"] >= no_workers_timeout:
                raise _Stopped(f"the cluster at {address} had no worker for {no_workers_timeout:.0f} s")

        def next_done():
            """The next task done, looking at the cluster every :data:`_WATCH` seconds."""
            while True:
                if time.monotonic() >= watch["next"]:
                    look()
                    watch["next"] = time.monotonic() + _WATCH
                if queue.has_ready():
                    return next(queue)
                time.sleep(0.01)

        def result_of(fut):
            """A done task's result; the workers holding it may be lost meanwhile, and Dask
            then computes it again: looking at the cluster while it waits."""
            while True:
                try:
                    return fut.result(timeout=_WATCH)
                except DaskTimeoutError:
                    if fut.status == "error":       # the task's own TimeoutError
                        raise
                    look()

        told = set()                            # the reasons of cancelled tasks said
        clock["start"], cpu = time.perf_counter(), time.process_time()
        while len(inflight) < watch["limit"] and submit():
            pass
        while inflight:
            fut = next_done()
            name, part, attempt = inflight.pop(fut)
            _moment("completed", client=client, future=fut)
            try:
                result = result_of(fut)
            except FutureCancelledError as exc:
                # not the task's doing (its inputs or the scheduler were lost): again, uncounted
                if client.status == "closed":
                    raise _Stopped(f"the connection to the scheduler at {address} was lost") from None
                failures.append(first_line(exc) or type(exc).__name__)
                if exc.reason == "lost dependencies":
                    shipped.pop("inputs", None)     # the scheduler forgot them: submitted anew
                retry.append((name, part, attempt))
                if prog is not None and exc.reason not in told:
                    told.add(exc.reason)            # once until a task completes again
                    prog.say(f"sweep: tasks cancelled by Dask ({exc.reason}); running them again")
            except Exception as exc:                # noqa: BLE001 - any failure of a task is retried
                failures.append(first_line(exc) or type(exc).__name__)
                if attempt < _ATTEMPTS:
                    retry.append((name, part, attempt + 1))
                    if prog is not None:
                        prog.say(f"sweep: a task of {len(part)} runs failed ({failures[-1]}); "
                                 f"running it again (attempt {attempt + 1} of {_ATTEMPTS})")
            else:
                collect(name, result)
                told.clear()
            fut.release()
            while len(inflight) < watch["limit"] and submit():
                pass
        clock["end"], clock["cpu"] = time.perf_counter(), time.process_time() - cpu
    except _Stopped as exc:
        stopped.append(str(exc))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return where, cores
