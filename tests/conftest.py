"""Shared pytest configuration: make ``tests/scenes.py`` importable in any import mode, and
keep the bytecode of what the tests import, and compile kernels ahead on a cold cache."""

import contextlib
import logging
import os
import sys
import warnings

import pytest

sys.path.insert(0, os.path.dirname(__file__))

# Where PYTHONDONTWRITEBYTECODE is set no process writes bytecode: pytest would rewrite the
# asserts of every test module again each session (about 2 s), and every process a test
# starts (command line, batch and Dask workers, numba's compile-ahead helper) would compile
# rtmesh's 25,000 lines from source again (about 0.15 s each).  This process writes it, into
# the __pycache__ folders (ignored by git, already holding numba's caches), as rtmesh and
# the test modules are imported during collection, before any test starts a process; the
# others read it.  Python checks each file's time and size against its source, so an edited
# module never runs stale.
sys.dont_write_bytecode = False


# The session runs inside compile_ahead.helper(), as the rtmesh command runs a render: on a
# cold numba cache (CI installs from scratch) a helper process compiles each kernel group a
# render announces from its end while the render compiles it from its start, on the second
# core.  The path kernel, the largest compile by far (about 34 s of one core, one
# function), is announced at once, so the helper compiles it while the first tests run;
# the first path render waits for what remains (its lock file) and loads it from the disk
# cache.  With a warm cache no helper starts.  Every render computes what it computes
# outside the block: the helper only fills the disk cache.  Under pytest-xdist each worker
# process has its own block (and helper); the lock files keep two processes from compiling
# a grouped kernel twice.
_session = contextlib.ExitStack()


def pytest_configure(config):
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return  # pytest-xdist's controller: its workers run the tests
    from rtmesh.core import compile_ahead
    from rtmesh.rendering.caustics import PHOTON_KERNELS
    from rtmesh.rendering.path_kernel import PATH_KERNELS

    _session.enter_context(compile_ahead.helper())
    PATH_KERNELS.compile_ahead()
    PHOTON_KERNELS.compile_ahead()


def pytest_unconfigure(config):
    _session.close()


@pytest.fixture
def cli(capsys, caplog):
    """Run the ``rtmesh`` command in this process, as ``python -m rtmesh.cli ARGS`` would:
    ``cli(*args)`` returns (exit status, stdout, stderr).

    For the tests of what a command says, not of the process: a process costs about 1 s
    of CPU to import rtmesh (the tests of the real entry point run one).  argparse's
    SystemExit gives its status.  What a process would print to stderr and pytest catches
    here is added to stderr, so a stray line still breaks a one-line check: the command's
    log records of WARNING and above (its ``logging.basicConfig`` handler, which pytest's
    own handlers pre-empt), and Python warnings a process shows (not the deprecation,
    import and resource warnings its default filters hide; a RuntimeWarning still fails
    the test, as the suite's filter says).
    """
    from rtmesh.cli import main

    hidden = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)

    def run(*args):
        capsys.readouterr()
        caplog.clear()
        with caplog.at_level(logging.WARNING), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.simplefilter("error", RuntimeWarning)
            try:
                code = main([str(a) for a in args])
            except SystemExit as exc:
                code = exc.code
        out, err = capsys.readouterr()
        err += "".join(f"rtmesh: warning: {r.getMessage()}\n" for r in caplog.records
                       if r.levelno >= logging.WARNING)
        err += "".join(f"{w.filename}:{w.lineno}: {w.category.__name__}: {w.message}\n" for w in caught
                       if not issubclass(w.category, hidden))
        return code, out, err

    return run


@pytest.fixture
def in_process_jobs():
    """Local batches of the test run their jobs in the test process, not in worker
    processes (tests/local_jobs.py): for tests that are not about the pool."""
    from local_jobs import jobs_in_this_process

    with jobs_in_this_process():
        yield
