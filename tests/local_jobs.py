"""Run a local batch's jobs in the test process.

A local batch (``rtmesh.batch_convert`` without a scheduler) hands its jobs to
:func:`rtmesh.batch.pool.run_local`, which starts worker processes; each one imports rtmesh
and renders a warm-up asset before its first job, about 1.7 s of CPU per batch, several
times what the tiny assets of most tests cost.  Tests about the ledger, names, resumes,
fingerprints and outputs do not depend on where a job runs: with :func:`jobs_in_this_process`
(or the ``in_process_jobs`` fixture of tests/conftest.py) the same jobs go through the same
:func:`rtmesh.batch.worker.run_job` as in a worker, their results through the same
callbacks, and every job and result makes the round trip through pickle that the worker's
pipe makes.  The tests of the pool itself (worker processes, time
and memory limits, a killed worker, signals, the command in a process of its own) keep the
real pool: they do not use this.
"""

import contextlib
import pickle
import time

import pytest

from rtmesh.batch import pool


def run_jobs_here(jobs, workers, on_image, on_job, time_limit=None, memory_limit=None):
    """:func:`rtmesh.batch.pool.run_local`'s contract, one job after another in this process.

    The time limit is the job's deadline between render chunks (as on a Dask worker); the
    memory limit (RLIMIT_AS of a worker process) is not applied: the tests of both limits
    use the real pool.
    """
    for job in jobs:
        job = pickle.loads(pickle.dumps(job))  # as sent down the worker's pipe
        deadline = time.monotonic() + time_limit if time_limit else None
        result = pool.run_job(job, on_image=lambda image: on_image(pickle.loads(pickle.dumps(image))),
                              deadline=deadline)
        on_job(pickle.loads(pickle.dumps(result)))


@contextlib.contextmanager
def jobs_in_this_process():
    """Local batches started inside run their jobs in this process (for module fixtures)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pool, "run_local", run_jobs_here)
        yield
