"""Dask batch runner: the jobs of a batch on a dask.distributed cluster.

It takes the same :class:`~rtmesh.batch.jobs.AssetJob` list as the local pool
(:mod:`rtmesh.batch.pool`) and reports through the same callbacks, in the submitting
process.  On a cluster the workers write the images into the output folder, which must be
the same storage for them and for the submitting machine; and the cluster can outlive or
lose the submitting process.  So:

- **Storage probe**: before dispatching, every worker writes a probe file with a random
  token into the output folder and checks that it can read an input; the submitter reads
  each probe back.  An accepted worker is given a Dask resource named after the output
  folder, which every job of the batch requires; a refused worker gets one warning line
  and no job.  Workers that join later (a restarted worker) are probed the same way within
  a few seconds.  No accepted worker: the batch stops before any job, with one line.  (The
  submitter also checks every image a job reports, size and checksum, see
  :class:`rtmesh.batch.Books`; a job that cannot see the batch's run file is failed the
  same way.)
- **Runs**: the workers never put an image in place: they leave its files at temporary
  names, and the submitting process renames them once it has recorded the image
  (:mod:`rtmesh.batch.publish`), so a task of an earlier run whose submitter was killed
  cannot write an image, however long it goes on.  To free the cluster, task keys name the
  output folder and the run (``rtmesh-batch-<folder>-<run>-<n>``): a resumed run cancels
  the earlier runs' tasks of its folder, queued or running, without waiting for them, and
  a task stops at its next check (between render chunks) once the scheduler has dropped
  it or the run file (``OUTDIR/.rtmesh-batch-run``, written by the submitter when it takes
  the folder) names another run.
- **Cluster loss**: losing the scheduler raises :class:`ClusterLost`; the jobs not
  finished are left for a resume, not recorded as failed.
- **Warm workers**: accepted workers render a tiny scene before the first job
  (:func:`rtmesh.batch.worker.warm_up`), first one worker per host, then the others: on a
  fresh node the kernels are compiled once into numba's disk cache, which the node's other
  workers then load, instead of every worker process compiling them at the same time.  The
  first worker compiles with a helper process on another core
  (:func:`rtmesh.core.compile_ahead.helper`): 7.8 s instead of 11.4 s on a 2-core host.
"""

import hashlib
import logging
import os
import secrets
import threading
import time
from concurrent.futures import CancelledError

from rtmesh.batch.worker import current_run, image_result, run_job, warm_up
from rtmesh.core import compile_ahead, runtime
from rtmesh.core.errors import RtmeshError

log = logging.getLogger("rtmesh.batch.runner")

DASK_MISSING = "--scheduler needs dask.distributed: pip install rtmesh[distributed]"
KEY_PREFIX = "rtmesh-batch-"


class ClusterLost(RtmeshError):
    """The connection to the Dask scheduler was lost in the middle of a batch."""


def run_dask(jobs, scheduler, on_image, on_job, run="", outdir=None, time_limit=None,
             retries=2):
    """Run jobs on a dask.distributed cluster; results come back to this process.

    Parameters
    ----------
    jobs : sequence of AssetJob
    scheduler : str or distributed.Client
        Scheduler address (``tcp://host:8786``) or a connected client.
    on_image, on_job : callable
        Called here, in the client, as each job's result arrives.
    run : str
        The batch's run id (in the task keys).
    outdir : str, optional
        The output folder the workers must share with this machine (default: the jobs').
    time_limit : float, optional
        Seconds per job, enforced inside the task between render chunks (a Dask task cannot
        be killed from outside without killing its worker).  Memory is guarded by the
        cluster's own per-worker ``memory_limit``.
    retries : int
        Extra attempts for a task that raised (a task lost with a killed worker is re-run by
        the scheduler without counting as a retry).

    Raises
    ------
    RtmeshError
        dask.distributed is not installed, the scheduler cannot be reached, or no worker
        can write the output folder so that this machine sees it.
    ClusterLost
        The scheduler went away; jobs whose results had not arrived are not reported.
    """
    if not jobs:
        return
    try:
        from distributed import Client  # noqa: F401
    except ImportError:
        raise RtmeshError(DASK_MISSING) from None
    # the client's own log (reconnection attempts, tracebacks of a lost connection) would
    # bury the batch's one-line messages: it speaks only for critical errors meanwhile
    names = ["distributed"] + [n for n in logging.root.manager.loggerDict
                               if n.startswith("distributed.")]
    levels = {n: logging.getLogger(n).level for n in names}
    for name in names:
        logging.getLogger(name).setLevel(logging.CRITICAL)
    try:
        _run(jobs, scheduler, on_image, on_job, run, outdir, time_limit, retries)
    finally:
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)


def _run(jobs, scheduler, on_image, on_job, run, outdir, time_limit, retries):
    from distributed import Client, as_completed

    outdir = outdir or jobs[0].outdir
    own_client = not isinstance(scheduler, Client)
    if own_client:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise RtmeshError(f"cannot reach the Dask scheduler at {scheduler}: "
                              f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
    else:
        client = scheduler
    prober = None
    try:
        resource = storage_resource(outdir)
        try:
            prober = Prober(client, outdir, jobs[0].path, resource)
            cancel_earlier_runs(client, outdir, run)
        except (OSError, TimeoutError, CancelledError) as exc:
            raise ClusterLost(f"cluster lost: {_one_line(exc)}") from None
        warm_up_workers(client, prober.accepted)
        prober.start()
        prefix = task_prefix(outdir, run)
        futures = {client.submit(_dask_task, job, time_limit, key=f"{prefix}{i}",
                                 pure=False, retries=retries, resources={resource: 1}): job
                   for i, job in enumerate(jobs)}
        try:
            for future in as_completed(futures):
                job = futures[future]
                try:
                    result = future.result()
                except Exception as exc:
                    if _lost(client, exc):
                        raise ClusterLost("cluster lost") from None
                    # the task itself failed: e.g. KilledWorker
                    message = _one_line(exc)
                    result = {"asset": job.asset, "seconds": 0.0, "images": [
                        image_result(job, t, "failed", 0.0, stage="worker", message=message)
                        for t in job.images]}
                finally:
                    future.release()
                if result.get("superseded"):
                    # this run owns the folder: a job that reads another run id there does
                    # not see the folder this machine sees
                    result = {"asset": job.asset, "seconds": result["seconds"], "images": [
                        image_result(job, t, "failed", 0.0, stage="storage",
                                     message="output not visible to the submitting machine: the "
                                     "worker does not see this batch's run file")
                        for t in job.images]}
                for image in result["images"]:
                    on_image(image)
                on_job(result)
        except ClusterLost:
            raise
        except (OSError, TimeoutError, CancelledError) as exc:
            if _lost(client, exc):
                raise ClusterLost("cluster lost") from None
            raise
    finally:
        if prober is not None:
            prober.stop()
        if own_client:
            try:
                client.close(timeout=5)
            except Exception:  # noqa: BLE001 - closing a client of a dead scheduler
                pass


def _lost(client, exc):
    """True when ``exc`` means the scheduler is gone, not that one task failed: the client
    cancels every future when it loses the scheduler (a task's own error, such as a worker
    killed too often, comes as that error)."""
    try:
        from distributed.comm.core import CommClosedError
    except ImportError:  # pragma: no cover
        CommClosedError = ConnectionError
    return isinstance(exc, (CancelledError, CommClosedError)) or client.status != "running"


def storage_resource(outdir):
    """Name of the Dask resource that marks workers proven to share ``outdir``."""
    return "rtmesh-storage-" + _folder_tag(outdir)


def task_prefix(outdir, run=""):
    """Key prefix of the batch tasks writing into ``outdir`` (of run ``run``, if given)."""
    return f"{KEY_PREFIX}{_folder_tag(outdir)}-" + (f"{run}-" if run else "")


def _folder_tag(outdir):
    return hashlib.sha1(os.fspath(outdir).encode()).hexdigest()[:12]


class Prober:
    """Probes the cluster's workers (now, then every few seconds for new ones in a thread)
    and gives those that pass the storage resource.

    Raises
    ------
    RtmeshError
        On creation, when no worker passes.
    """

    def __init__(self, client, outdir, sample_input, resource, every=2.0):
        self.client, self.outdir, self.sample, self.resource = client, outdir, sample_input, resource
        self.every, self.seen, self._stop = every, set(), threading.Event()
        self._thread = None
        accepted, reasons = self.probe()
        self.accepted = accepted
        if not accepted:
            raise RtmeshError(f"no Dask worker can write {outdir} so that this machine sees "
                              f"the images ({len(reasons)} refused: {next(iter(reasons.values()), 'no worker')})")

    def probe(self):
        """Probe the workers not seen yet; returns (accepted addresses, refusal reasons)."""
        workers = [w for w in _workers(self.client) if w not in self.seen]
        if not workers:
            return [], {}
        self.seen.update(workers)
        accepted, reasons, probes = probe_workers(self.client, self.outdir, self.sample, workers)
        grants = {w: 1 for w in accepted}
        grants.update({w: 0 for w in reasons})  # a worker refused now loses an older grant
        self.client.run(_grant, self.resource, grants, probes, workers=workers, on_error="return")
        for worker, reason in reasons.items():
            log.warning("Dask worker %s refused: %s", worker, reason)
        if self._thread is not None and accepted:  # joined during the batch
            warm_up_workers(self.client, accepted)
        return accepted, reasons

    def start(self):
        self._thread = threading.Thread(target=self._loop, name="rtmesh-dask-prober", daemon=True)
        self._thread.start()

    def _loop(self):
        while not self._stop.wait(self.every):
            try:
                self.probe()
            except Exception:  # noqa: BLE001 - a lost cluster is the main loop's to report
                return

    def stop(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)


def warm_up_workers(client, workers):
    """Warm up ``workers``: one per host first (it fills the host's kernel cache), then the
    rest at once.  A worker that fails to warm up is left to fail its jobs on its own."""
    first = {}
    for worker in workers:
        first.setdefault(_host(worker), worker)
    for group in (list(first.values()), [w for w in workers if w not in first.values()]):
        if group:
            client.run(_warm_up_task, workers=group, on_error="return")


def _host(address):
    from urllib.parse import urlsplit

    return urlsplit(address).hostname or address


def _warm_up_task():
    runtime.tune_process()
    # no job runs on the worker yet: on a first run, a helper process compiles half of the
    # kernels on another core (the host's other workers wait for this one)
    with compile_ahead.helper():
        warm_up()


def _workers(client):
    import inspect

    if "n_workers" in inspect.signature(client.scheduler_info).parameters:
        return list(client.scheduler_info(n_workers=-1)["workers"])
    return list(client.scheduler_info()["workers"])


async def _grant(resource, grants, probes, dask_worker=None):
    """On a worker: remove its probe file (from its own view of the folder), and hold
    ``resource`` (as many as it has threads) if granted, else none."""
    if probes.get(dask_worker.address):
        try:
            os.unlink(probes[dask_worker.address])
        except OSError:
            pass  # the submitter removed it: the folder is shared
    if dask_worker.address in grants:
        await dask_worker.set_resources(
            **{resource: dask_worker.state.nthreads * grants[dask_worker.address]})


def probe_workers(client, outdir, sample_input, workers):
    """Which workers can read ``sample_input`` and write ``outdir`` visibly to this machine.

    Returns
    -------
    accepted : list of str
    reasons : dict of str to str
        Why each other worker was refused (one line).
    probes : dict of str to str
        The probe file each worker wrote (for it to remove).
    """
    tokens = {w: secrets.token_hex(8) for w in workers}
    answers = client.run(_probe, outdir, sample_input, tokens, workers=workers, on_error="return")
    accepted, reasons, probes = [], {}, {}
    for worker in workers:
        answer = answers.get(worker)
        if isinstance(answer, BaseException) or answer is None:
            reasons[worker] = f"probe failed: {_one_line(answer)}"
            continue
        name, problem = answer
        path = os.path.join(outdir, name) if name else None
        if problem:
            reasons[worker] = problem
        elif current_run(path) != tokens[worker]:
            reasons[worker] = (f"its probe file {name} did not appear in {outdir} on this machine: "
                               f"the worker's output folder is not this machine's (shared storage?)")
        else:
            accepted.append(worker)
        if path:
            probes[worker] = path
            try:
                os.unlink(path)
            except OSError:
                pass
    return accepted, reasons, probes


def _probe(outdir, sample_input, tokens, dask_worker=None):
    """On a worker: read an input, write a probe file; returns (file name, problem)."""
    token = tokens.get(dask_worker.address if dask_worker is not None else "", "")
    try:
        with open(sample_input, "rb") as f:
            f.read(1)
    except OSError as exc:
        return "", f"cannot read the inputs ({sample_input}: {exc.strerror})"
    name = f".rtmesh-batch-probe-{token}.tmp"
    try:
        with open(os.path.join(outdir, name), "w", encoding="utf-8") as f:
            f.write(token + "\n")
    except OSError as exc:
        return "", f"cannot write {outdir}: {exc.strerror}"
    return name, ""


def cancel_earlier_runs(client, outdir, run):
    """Cancel the tasks of other runs into ``outdir``, queued or running; returns how many.

    They could not put an image in place anyway (only their submitting process, now gone,
    could have); cancelling frees their workers: a running one stops between render chunks
    (:func:`_abandoned_check`).  Batches into other folders are left alone.
    """
    from distributed import Future

    keys = client.run_on_scheduler(_other_runs_tasks, task_prefix(outdir), task_prefix(outdir, run))
    if keys:
        client.cancel([Future(k, client) for k in keys], force=True)
    return len(keys)


def _other_runs_tasks(prefix, own, dask_scheduler=None):
    """On the scheduler: keys starting with ``prefix`` and not with ``own``."""
    return [key for key in dask_scheduler.tasks
            if isinstance(key, str) and key.startswith(prefix) and not key.startswith(own)]


def _dask_task(job, time_limit):
    """The function a Dask worker runs for one asset."""
    # a worker of an rtmesh batch renders: tune its process for that (once; idempotent)
    runtime.tune_process()
    deadline = time.monotonic() + time_limit if time_limit else None
    return run_job(job, deadline=deadline, abandoned=_abandoned_check())


def _abandoned_check():
    """A function telling whether this task was cancelled (its client gone, so the
    scheduler forgot it: a result would reach nobody and its images nobody's ledger)."""
    try:
        from distributed import get_worker
        from distributed.worker import thread_state

        worker, key = get_worker(), thread_state.key
    except (ImportError, ValueError, AttributeError):
        return None

    def abandoned():
        ts = worker.state.tasks.get(key)
        return ts is None or ts.state in ("cancelled", "released", "forgotten")

    return abandoned


def _one_line(exc):
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
