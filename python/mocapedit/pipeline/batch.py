"""Many shots solved with the same options on ``dask.distributed`` (``mocapedit batch``).

A batch is a list of :class:`Job` (one shot, one output), planned and checked before any
work starts (:func:`plan`), then run as one task per shot (:func:`solve_shot`) on a Dask
cluster: a local cluster of worker processes by default, or any running scheduler by its
address (``dask scheduler`` / ``dask worker``, dask-jobqueue on a farm, Kubernetes). Each
task is an ordinary :func:`mocapedit.pipeline.processor.solve` writing its edits layer atomically,
so a batch result is byte for byte what ``mocapedit solve`` writes for that shot named by
its absolute path (the layer records the input path as given).

One failing shot does not stop the others: its error goes into its :class:`ShotResult`.
A shot whose output already holds the same input content hash and the same options is
skipped (``force`` solves it anyway). With ``split``, a shot's independent path components, and its
agents' foot locking, are solved as tasks of their own (:class:`DaskComponents`), so a shot keeps
idle workers busy; its bytes are the same. Workers must see the shots and the output folder at
the same paths as the client (a shared file system) and have mocapedit installed.
"""
from __future__ import annotations

import contextlib
import os
import time
from dataclasses import asdict, dataclass, field

from mocapedit.usd import outputs
from mocapedit.model.errors import MocapEditError

#: Seconds to wait for a scheduler given by address before giving up.
CONNECT_TIMEOUT = 5.0
#: Seconds more for a reached scheduler to answer the handshake.
HANDSHAKE_SLACK = 1.0
#: Dask's configuration of the environment its nannies give new worker processes.
WORKER_ENVIRON = "distributed.nanny.pre-spawn-environ"
#: File name of the summary written in the output folder.
SUMMARY = "batch-summary.json"


@dataclass(frozen=True)
class Job:
    shot: str            # absolute path of the input stage
    output: str          # absolute path of the edits layer to write


@dataclass
class ShotResult:
    shot: str
    output: str
    status: str                      # "solved" | "skipped" | "failed"
    seconds: float = 0.0
    error: str | None = None
    contentHash: str | None = None
    figures: dict = field(default_factory=dict)
    componentTasks: int = 0          # tasks its path components were solved in (0: in its own)
    notes: list[str] = field(default_factory=list)   # the shot's notes, as solve prints them


def output_name(shot: str, suffix: str) -> str:
    """``shots/a.usda`` -> ``a.edits.usdc`` for suffix ``.edits.usdc``."""
    return os.path.splitext(os.path.basename(shot))[0] + suffix


def plan(shots: list[str], outdir: str, suffix: str = ".edits.usdc", summary: str | None = None) -> list[Job]:
    """The jobs of a batch, checked before any work starts.

    ``summary``: where the summary will be written (default ``OUTDIR/batch-summary.json``);
    checked with the edits layers.

    Raises:
      MocapEditError: no shots, a shot path that is not a file, two shots that would
        write the same output, or an output (an edits layer or the summary) that would
        overwrite a file some shot reads (the shot, its sub-layers, clips and other
        dependencies) or another output.
    """
    if not shots:
        raise MocapEditError("batch: no shots given")
    if "/" in suffix or os.sep in suffix or (os.altsep and os.altsep in suffix):
        raise MocapEditError(f"--suffix '{suffix}': names a folder; a suffix ends the shot's file name "
                             "(e.g. .edits.usdc), and the layers go into OUTDIR")
    jobs, by_output = [], {}
    for shot in shots:
        path = os.path.abspath(shot)
        if not os.path.isfile(path):
            raise MocapEditError(f"{shot}: no such shot file")
        output = os.path.abspath(os.path.join(outdir, output_name(path, suffix)))
        if output in by_output:
            raise MocapEditError(f"{shot} and {by_output[output]} would both write {output}; "
                                 "give the shots different file names or run them in separate batches")
        by_output[output] = shot
        jobs.append(Job(path, output))
    inputs = {j.shot for j in jobs}
    for job in jobs:
        if job.output in inputs:
            raise MocapEditError(f"{job.output}: the output would overwrite an input shot")
    # Every output against every file any shot reads (each solve checks its own shot's
    # layers again, as it opens them).
    reads = sorted({f for j in jobs for f in outputs.dependency_files(j.shot)})
    outputs.check_outputs([outputs.Output(j.output, "-o/--suffix") for j in jobs] +
                          [outputs.Output(summary or os.path.join(outdir, SUMMARY), "--summary", kind="text",
                                          extensions=(".json",))], reads)
    return jobs


def _figures(report) -> dict:
    stats = report.stats
    hard = [c.get("residual") or 0.0 for c in report.constraints if c.get("hard")]
    figures = {k: stats[k] for k in ("agents", "editedAgents", "constraints", "remainingOverlaps")
               if k in stats}
    figures["worstHardResidual"] = max(hard, default=0.0)
    return figures


class DaskComponents:
    """A :class:`~mocapedit.pipeline.context.ComponentPool` on a ``distributed.Client``: each run of
    path components, or of agents to lock the feet of, is one task, gathered back in order."""

    def __init__(self, client, chunks: int | None = None):
        self.client = client
        #: Two runs per worker, so a run that takes longer leaves the other worker another one.
        self.chunks = chunks or 2 * max(1, len(client.scheduler_info().get("workers", {})))
        #: Tasks submitted so far.
        self.tasks = 0

    def map(self, fn, items: list) -> list:
        self.tasks += len(items)
        # Sent as data, not inside the task graph (a 1,000-agent shot's runs are tens of MB).
        data = self.client.scatter(items, hash=False)
        return self.client.gather(self.client.map(fn, data, pure=False))


@contextlib.contextmanager
def _component_pool(split: bool):
    """Where a shot's path components and foot locking run: on the cluster this task runs on (``split``),
    else (or outside any cluster) in the shot's own process (None)."""
    if split:
        from distributed import get_worker
        try:
            get_worker()
        except ValueError:
            split = False
    if not split:
        yield None
        return
    from distributed import worker_client
    with worker_client() as client:   # leaves the worker's thread to the component tasks
        yield DaskComponents(client)


def solve_shot(job: Job, options: dict, force: bool = False, split: bool = False) -> ShotResult:
    """Solves one shot (a Dask task; also runs in-process). Never raises: a failure is a
    result with its error. ``split``: the shot's path components and foot locking are solved as
    tasks of their own on the same cluster (in-process, in the shot's process)."""
    from mocapedit.pipeline import processor
    from mocapedit.usd import edits_format, reader
    t = time.perf_counter()
    result = ShotResult(shot=job.shot, output=job.output, status="failed")
    try:
        if not force and os.path.isfile(job.output):
            stage = reader.open_stage(job.shot)
            digest = processor.content_hash(stage)
            if edits_format.recorded(job.output) == (digest, processor.options_text(**options)):
                result.status, result.contentHash = "skipped", digest
                return result
        with _component_pool(split) as pool:
            solved = processor.solve(job.shot, output=job.output, components=pool, **options)
            result.componentTasks = pool.tasks if pool is not None else 0
        result.status = "solved"
        result.figures = _figures(solved.report)
        result.notes = list(solved.report.notes)
        result.contentHash = edits_format.content_hash(solved.layer)
    except MocapEditError as exc:
        result.error = str(exc)
    except Exception as exc:  # any other failure of one shot is reported, the batch goes on
        result.error = f"{type(exc).__name__}: {exc}"
    finally:
        result.seconds = round(time.perf_counter() - t, 3)
    return result


def _client_of(client_type, scheduler: str):
    """A client connected to ``scheduler`` within :data:`CONNECT_TIMEOUT` seconds (and a few more
    for the handshake, which Dask's own timeout does not bound: a port that accepts and never
    answers held it for ever), or a MocapEditError that says what the address is not."""
    import queue
    import threading
    got: queue.Queue = queue.Queue()

    def attempt() -> None:
        try:
            got.put((client_type(scheduler, timeout=CONNECT_TIMEOUT), None))
        except BaseException as exc:   # whatever the bytes there made Dask raise, said below
            got.put((None, exc))

    threading.Thread(target=attempt, name="mocapedit-connect", daemon=True).start()
    try:
        client, exc = got.get(timeout=CONNECT_TIMEOUT + HANDSHAKE_SLACK)
    except queue.Empty:
        raise MocapEditError(f"--scheduler {scheduler}: something listens there but did not answer as a Dask "
                             f"scheduler within {CONNECT_TIMEOUT + HANDSHAKE_SLACK:g} s; check the address "
                             "(the scheduler's port, 8786 by default, not its dashboard's)") from None
    if exc is None:
        return client
    if isinstance(exc, (OSError, TimeoutError)):
        raise MocapEditError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there within "
                             f"{CONNECT_TIMEOUT:g} s ({type(exc).__name__}); start one with "
                             "`dask scheduler` or check the address") from None
    if isinstance(exc, ValueError) and "://" not in scheduler:
        raise MocapEditError(f"--scheduler {scheduler}: {exc}") from None
    raise MocapEditError(f"--scheduler {scheduler}: what answered there is not a Dask scheduler "
                         f"({type(exc).__name__}); check the address (the scheduler's port, 8786 by default, "
                         "not its dashboard's)") from None


def connect(scheduler: str | None, workers: int | None):
    """A ``distributed.Client``: to ``scheduler`` (``tcp://host:port``) or to a new local
    cluster of ``workers`` single-threaded processes, whose solvers share the cores
    (``MOCAPEDIT_THREADS``: the caller's, else the cores over the workers). Returns (client,
    cluster or None).

    Raises:
      MocapEditError: the scheduler cannot be reached within :data:`CONNECT_TIMEOUT` seconds.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise MocapEditError("mocapedit batch runs on dask.distributed, which is not installed: "
                             "pip install 'mocapedit[batch]' (or dask[distributed])") from None
    if scheduler:
        return _client_of(Client, scheduler), None
    import dask
    from mocapedit.solve import threads
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    n = workers or max(1, min(cores, 8))
    # Workers forked from a fresh server process start in about a second; spawned ones, which
    # import everything again, took four (and a batch of small shots waits for them).
    # Dask sets MALLOC_TRIM_THRESHOLD_ in its workers, which turns off glibc's reuse of freed
    # large blocks: every array then comes from fresh zeroed pages (twice the page faults of
    # a solve). A solve hands its freed memory back itself after each phase (memory.give_back).
    # Each worker's solver threads get its share of the cores, unless the caller set
    # MOCAPEDIT_THREADS: two workers on two cores, each solving on two threads, took 6% longer
    # per shot than on one thread each. Given to the workers alone (what the pre-spawn
    # environment holds is also set in this process, and forked workers would keep the
    # environment of the first cluster).
    env = {threads.ENVIRONMENT: str(threads.check_environment() or max(1, cores // n))}
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver",
                          f"{WORKER_ENVIRON}.MALLOC_TRIM_THRESHOLD_": None}):
        # No dashboard, and the scheduler's HTTP routes on a free port: its default, 8787, is
        # often held by a dashboard or another batch on the same machine.
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"}, env=env)
    return Client(cluster), cluster


def run(jobs: list[Job], options: dict, client, force: bool = False, on_result=None,
        split: bool = False) -> list[ShotResult]:
    """Runs the jobs on a Dask ``client``, one task per shot, and returns their results in
    job order. ``on_result(result, done, failed, remaining)`` is called as each finishes.
    ``split``: each shot's path components and foot locking are tasks of their own too (see :func:`solve_shot`)."""
    from distributed import as_completed
    futures = {client.submit(solve_shot, job, options, force, split, key=f"mocapedit-shot-{i}-{job.output}",
                             pure=False): i for i, job in enumerate(jobs)}
    results: list[ShotResult | None] = [None] * len(jobs)
    done = failed = 0
    for future in as_completed(futures):
        i = futures[future]
        try:
            result = future.result()
        except Exception as exc:  # the worker itself died (killed, out of memory)
            result = ShotResult(shot=jobs[i].shot, output=jobs[i].output, status="failed",
                                error=f"worker lost: {type(exc).__name__}: {exc}")
        results[i] = result
        done += 1
        failed += result.status == "failed"
        if on_result:
            on_result(result, done, failed, len(jobs) - done)
    return results


def written_since(jobs: list[Job], since: float) -> list[str]:
    """The jobs' edits layers written at or after ``since`` (a ``time.time()``), in job order."""
    out = []
    for job in jobs:
        try:
            if os.stat(job.output).st_mtime >= since - 1.0:   # file systems keep coarse times
                out.append(job.output)
        except OSError:
            pass
    return out


def summary(results: list[ShotResult], options: dict, seconds: float) -> dict:
    counts = {s: sum(r.status == s for r in results) for s in ("solved", "skipped", "failed")}
    return {"options": options, "shots": [asdict(r) for r in results], "seconds": round(seconds, 3),
            **counts}
