"""Local batch runner: a pool of worker processes on this machine.

It takes the same :class:`~rtmesh.batch.jobs.AssetJob` list as the Dask runner
(:mod:`rtmesh.batch.dask_pool`) and reports through the same two callbacks,
``on_image(image_result)`` and ``on_job(job_result)``, always called in the calling process:
the caller alone writes the ledger, so a batch leaves the same ledger wherever it ran.

The local pool is not :class:`concurrent.futures.ProcessPoolExecutor` because that pool
cannot stop one runaway job: it can only be shut down whole, and a worker that dies breaks
it.  Here each worker process has its own pipe, so the pool knows which job each one holds,
kills only the worker whose job ran past its time limit (or replaces one that died, say
from running out of memory), records that job as failed and carries on.
"""

import logging
import multiprocessing
import os
import resource
import signal
import threading
import time
from collections import deque
from multiprocessing.connection import wait

from rtmesh.batch import view_scenes
from rtmesh.batch import worker as batch_worker
from rtmesh.batch.worker import image_result, run_job
from rtmesh.core import compile_ahead, runtime
from rtmesh.core.errors import RtmeshError


def run_local(jobs, workers, on_image, on_job, time_limit=None, memory_limit=None):
    """Run jobs on ``workers`` local processes, each job under a time and memory limit.

    Parameters
    ----------
    jobs : sequence of AssetJob
    workers : int
    on_image, on_job : callable
        Called in this process as each image and each job finishes (or fails).
    time_limit : float, optional
        Seconds one job (one asset) may take; its worker is killed after that.
    memory_limit : int, optional
        Bytes of address space per worker process (``RLIMIT_AS``); allocations beyond it
        fail inside the worker, which reports the asset as failed at the ``memory`` stage.
    """
    if not jobs:
        return  # no worker process for no job
    pending = deque(jobs)
    # spawn, not fork: a fork of a process that has run thread pools (Embree, NumPy) can
    # inherit locks held by threads that no longer exist
    context = multiprocessing.get_context("spawn")
    size = max(1, min(workers, len(pending)))
    # one worker first: it warms up (compiles the kernels into numba's disk cache on a fresh
    # machine) before it says it is ready, and the others start after it, so they load the
    # compiled kernels instead of each compiling them again (once per node, not per process)
    pool = [_Worker(context, memory_limit)]
    failed_starts = 0
    try:
        while pending or any(w.job for w in pool):
            if len(pool) < size and any(w.ready for w in pool):
                pool += [_Worker(context, memory_limit) for _ in range(size - len(pool))]
            for i, worker in enumerate(pool):
                if worker.process.is_alive() or worker.job is not None:
                    continue
                # died before or between jobs (its job, if any, is handled below)
                if not worker.ready:
                    failed_starts += 1
                    if failed_starts >= 3 * len(pool):
                        reason = _death_reason(worker.process.exitcode, memory_limit)
                        raise RtmeshError(f"batch worker processes cannot start: {reason}")
                worker.close()
                pool[i] = _Worker(context, memory_limit)
            for worker in pool:
                # only a worker that has started gets a job: the time limit is the job's own
                # time, not the seconds a new process spends importing NumPy and Embree
                if worker.ready and worker.job is None and pending:
                    worker.assign(pending.popleft(), time_limit)
            watched = [w for w in pool if w.job is not None or not w.ready]
            deadlines = [w.deadline for w in watched if w.deadline is not None]
            timeout = max(0.0, min(deadlines) - time.monotonic()) if deadlines else None
            wait([w.conn for w in watched] + [w.process.sentinel for w in watched], timeout)
            for i, worker in enumerate(pool):
                if not worker.ready:
                    worker.check_ready()
                    continue
                if worker.job is None:
                    continue
                finished = worker.drain(on_image, on_job)
                if finished:
                    continue
                if not worker.process.is_alive():
                    reason = _death_reason(worker.process.exitcode, memory_limit)
                    worker.fail_rest("crash", reason, on_image, on_job)
                elif worker.deadline is not None and time.monotonic() > worker.deadline:
                    worker.process.kill()
                    worker.process.join()
                    worker.fail_rest("time", f"time limit of {time_limit:g} s exceeded", on_image, on_job)
                else:
                    continue
                worker.close()
                pool[i] = _Worker(context, memory_limit)
    finally:
        for worker in pool:
            worker.close()


class _Worker:
    """One worker process, its pipe and the job it holds."""

    def __init__(self, context, memory_limit):
        self.conn, child_conn = context.Pipe()
        self.process = context.Process(target=_worker_main, name="rtmesh-batch-worker",
                                       args=(child_conn, memory_limit, os.getpid()), daemon=True)
        self.process.start()
        child_conn.close()
        self.ready = False
        self.job, self.deadline, self.reported, self.start = None, None, set(), 0.0

    def check_ready(self):
        """Note the worker's "ready" message, sent once it has imported and set up."""
        try:
            if self.conn.poll():
                kind, _ = self.conn.recv()
                self.ready = kind == "ready"
        except (EOFError, OSError):
            pass  # died while starting: the pool replaces it

    def assign(self, job, time_limit):
        self.job, self.reported, self.start = job, set(), time.perf_counter()
        self.deadline = time.monotonic() + time_limit if time_limit else None
        self.conn.send(job)

    def drain(self, on_image, on_job):
        """Handle every message waiting; True once the job's final message has arrived."""
        while True:
            try:
                if not self.conn.poll():
                    return False
                kind, payload = self.conn.recv()
            except (EOFError, OSError):
                return False  # the worker died; the caller sees it from the exit code
            if kind == "image":
                self.reported.add(payload["key"])
                on_image(payload)
            else:
                self.job = None
                on_job(payload)
                return True

    def fail_rest(self, stage, message, on_image, on_job):
        """Report every image the worker had not finished as failed, then the job."""
        images = []
        for task in self.job.images:
            if task.key in self.reported:
                continue
            images.append(image_result(self.job, task, "failed", 0.0, stage=stage, message=message))
            on_image(images[-1])
        on_job({"asset": self.job.asset, "seconds": round(time.perf_counter() - self.start, 4),
                "images": images})
        self.job = None

    def close(self):
        if self.process.is_alive():
            try:
                self.conn.send(None)  # ask an idle worker to leave...
            except OSError:
                pass
            self.process.join(timeout=2.0)
            if self.process.is_alive():
                self.process.kill()  # ...and stop a busy one
                self.process.join()
        self.conn.close()


def _worker_main(conn, memory_limit, parent_pid):
    """Body of a worker process: take jobs from the pipe until told to stop."""
    # Ctrl-C reaches the whole process group; the parent decides what to stop
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with_parent(parent_pid)
    if memory_limit:
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        limit = memory_limit if hard == resource.RLIM_INFINITY else min(memory_limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
        view_scenes.set_memory_limit(limit)
    # warnings about a single asset's oddities would scramble the batch's progress bar
    logging.basicConfig(level=logging.ERROR)
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    # the process exists to render: tune it for that (allocator, GIL, kept threads)
    runtime.tune_process()
    try:
        # kernels compiled or loaded now, so the first job's time limit does not pay for them;
        # on a first run (the first worker, while the others wait for it) with a helper
        # process compiling half of them
        with compile_ahead.helper():
            batch_worker.warm_up()
    except Exception:  # noqa: BLE001 - the jobs report what is wrong (e.g. too little memory)
        pass
    conn.send(("ready", None))
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            break
        if job is None:
            break
        result = run_job(job, on_image=lambda image: conn.send(("image", image)))
        conn.send(("done", result))
    # every job's files are written and reported: the batch waits for this process to end,
    # and the interpreter's teardown would take a quarter of a second of it
    conn.close()
    runtime.end_process(0)


def _exit_with_parent(parent_pid):
    """Make sure no worker outlives the batch (say, after ``kill -9`` of the batch).

    An orphaned worker would go on writing images nobody records.  On Linux the kernel
    kills the worker with its parent (``PR_SET_PDEATHSIG``); elsewhere a watchdog thread
    notices the new parent within a second.
    """
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)

    def watchdog():
        while os.getppid() == parent_pid:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watchdog, daemon=True).start()


def _death_reason(exitcode, memory_limit):
    """One line on why a worker process ended in the middle of a job.

    A SIGKILL is named as such: the kernel's out-of-memory killer sends it, and so does a
    person or a cluster manager, so it is not called a memory failure.
    """
    if exitcode is not None and exitcode < 0:
        try:
            how = f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            how = f"killed by signal {-exitcode}"
    else:
        how = f"exited with status {exitcode}"
    limit = f" (limit {memory_limit / 2**30:.1f} GiB)" if memory_limit else ""
    if exitcode == -signal.SIGKILL:
        return f"worker process {how} (by the out-of-memory killer or another process)"
    # allocators that hit RLIMIT_AS abort or crash
    if exitcode in (-signal.SIGABRT, -signal.SIGSEGV) and memory_limit:
        return f"worker process {how}; out of memory?{limit}"
    return f"worker process {how}"
