"""Shared pytest configuration: make ``tests/scenes.py`` importable in any import mode, and
compile rtmesh's bytecode once per session."""

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))


def pytest_sessionstart(session):
    """Write the bytecode of the rtmesh under test (the ``__pycache__`` folders that hold
    numba's caches too, ignored by git) before anything imports it.

    Many tests start Python processes: the command line, batch workers, Dask workers,
    numba's compile-ahead helper.  Where ``PYTHONDONTWRITEBYTECODE`` is set no process
    writes bytecode, so each one would compile rtmesh's 25,000 lines from source again
    (about 0.2 s a process); with it written here they read it, and Python checks every
    file's time and size against its source, so an edited module is never run stale.
    """
    import compileall
    import importlib.util

    spec = importlib.util.find_spec("rtmesh")
    if spec is None or not spec.submodule_search_locations:
        return
    for folder in spec.submodule_search_locations:
        if os.access(folder, os.W_OK):
            compileall.compile_dir(folder, quiet=2, workers=1)
