"""Shared pytest configuration: make ``tests/scenes.py`` importable in any import mode, and
keep the bytecode of what the tests import."""

import os
import sys

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
