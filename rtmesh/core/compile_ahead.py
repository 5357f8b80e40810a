"""A first run's kernels, compiled by two processes at once.

The first render after an install (or after any kernel module changes, see
:mod:`rtmesh.core.compiled`) compiles every kernel it calls, and numba compiles one
function at a time per process: about 12 s on one core of a machine that has more.  A
:class:`KernelGroup` declares kernels with the signatures renders call them with, in the
order a render first calls them (the scene build's passes, the fused stage's steps, the
packet queries).  When a program turns the helper on (:func:`helper`, as the ``rtmesh``
command does while its cache is cold), a second Python process (:func:`helper_command`)
compiles each group that the render announces from its last kernel back, while the render
compiles it from its first on (:meth:`KernelGroup.prepare`); a lock file per kernel keeps
the two from compiling the same one, and numba's disk cache hands each kernel's machine
code to the other process.  They meet in the middle of a group.

Without a helper, :meth:`KernelGroup.prepare` still compiles a group the cache lacks under
the lock files (processes that render side by side on a first run, such as a batch's
workers, then compile each kernel once), but nothing runs ahead.  The helper only compiles: it never changes what a render
computes, and if it is killed half-way (numba writes its cache files whole, then renames
them) the render compiles what is missing itself.
"""

import contextlib
import importlib
import logging
import os
import subprocess
import sys
import threading

try:
    import fcntl
except ImportError:  # no advisory locks (Windows): the processes may compile a kernel twice
    fcntl = None

from rtmesh.core.runtime import usable_cores

log = logging.getLogger(__name__)

# every group, by name: the helper process finds a group the render announces here
_GROUPS = {}
# what the rtmesh command tells a user at a terminal when a first run compiles
FIRST_RUN_NOTE = ("rtmesh: compiling the renderer's kernels for this machine (once after an install, "
                  "up to a minute or so; later renders start at once)")
# within helper(): whether groups may be compiled ahead, and the helper process once
# started; the lock guards both and the helper's pipe
_enabled = False
_helper = None
_helper_lock = threading.Lock()


class KernelGroup:
    """Kernels with the signatures a render calls them with, in the order it first calls
    them.

    Parameters
    ----------
    module : str
        The module that declares the group (its ``__name__``): the helper process imports it.
    name : str
        Unique.
    kernels : sequence of (dispatcher, tuple of numba types)
        :func:`rtmesh.core.compiled.kernel` dispatchers (cached on disk) and one signature
        each.  A call with other argument types still works; it compiles that version on
        the spot, as any kernel call does.
    every_render : bool
        Every render prepares the group (the scene build's): while it is not cached, a
        first run is under way, and :func:`helper` starts the helper process at once
        rather than when a render first prepares a group the cache lacks.
    """

    def __init__(self, module, name, kernels, every_render=False):
        if name in _GROUPS:
            raise ValueError(f"kernel group {name!r} is declared twice")
        self.module = module
        self.name = name
        self.kernels = tuple((dispatcher, tuple(signature)) for dispatcher, signature in kernels)
        self.every_render = every_render
        self._prepared = False
        _GROUPS[name] = self

    def prepare(self):
        """If the disk cache lacks some of the group: compile the group's kernels from the
        first on, each holding its lock file (:func:`compile_locked`), so that a kernel
        another process is compiling is waited for and loaded rather than compiled twice
        (a batch's workers, or a render beside a test session's helper, on a first run).
        Within :func:`helper`, the helper process meanwhile compiles them from the last back
        (started now if it is not running).  With the group cached: nothing, the kernels
        load on their first call.

        Call it just before the render first calls the group's kernels.
        """
        with _helper_lock:
            if self._prepared:
                return
            self._prepared = True
        if self.cached():
            return
        # (the rtmesh command tells a user at a terminal, once: rtmesh.cli.first_run_note)
        log.info("compiling the %s kernels for this machine", self.name)
        _announce(self)
        for dispatcher, signature in self.kernels:
            compile_locked(dispatcher, signature)

    def compile_ahead(self):
        """Within :func:`helper`, if the disk cache lacks some of the group: have the helper
        process start compiling it now (from its last kernel back), well before a render
        calls :meth:`prepare` (which then waits for the kernel the helper is compiling and
        loads what it finished from the disk cache).  Otherwise nothing.

        For a program that knows early that it will need a large group, such as a test
        session (``tests/conftest.py``) and the path kernel.
        """
        with _helper_lock:
            if not _enabled or self._prepared:
                return
        if not self.cached():
            _announce(self)

    def compile_backwards(self):
        """Compile the group from its last kernel back (what the helper process does)."""
        for dispatcher, signature in reversed(self.kernels):
            compile_locked(dispatcher, signature)

    def cached(self):
        """Whether the disk cache holds every kernel of the group for its signature."""
        return all(_in_disk_cache(dispatcher, signature) for dispatcher, signature in self.kernels)


def groups():
    """Every kernel group declared so far (by the modules imported), in declaration order."""
    return tuple(_GROUPS.values())


def compile_locked(dispatcher, signature):
    """Compile ``dispatcher`` for ``signature``, or load it from the disk cache, holding
    the kernel's lock file: a process that finds the lock held waits, then loads what the
    other one compiled.

    Parameters
    ----------
    dispatcher : numba dispatcher with a disk cache
    signature : tuple of numba types
    """
    if signature in dispatcher.overloads:
        return
    # a compiled.kernel takes its lock file in every compile already
    lock_compiles(dispatcher).compile(signature)


def lock_compiles(dispatcher):
    """Make every compile of ``dispatcher`` hold its lock file (:func:`compile_locked`),
    also the compiles numba starts itself: a call from Python with new argument types, and
    the typing of another kernel that calls this one.

    Two processes of a first run (test workers, a render and its helper, a batch's workers)
    compile different kernels that call the same one (the BSDF dispatch, called by the
    light samples' stage and by the photon gather): without the lock both compiled it, about
    9 s of CPU each; with it the second waits, then loads it from the disk cache.

    numba's own compiler lock (one per process) is taken first: a thread that waits for
    the file holds it, so that no thread of this process can hold the file while it waits
    for numba's lock.  Kernels call each other without cycles, so two processes holding
    one lock file each never wait for each other's.

    Parameters
    ----------
    dispatcher : numba dispatcher with a disk cache
        Changed in place (its ``compile``; once: a second call changes nothing); returned.
    """
    if getattr(dispatcher, "_compiles_locked", False):
        return dispatcher
    from numba.core import sigutils
    from numba.core.compiler_lock import global_compiler_lock

    unlocked = dispatcher.compile

    def compile(sig):
        args, _ = sigutils.normalize_signature(sig)
        if tuple(args) in dispatcher.overloads:
            return unlocked(sig)
        with global_compiler_lock, _kernel_lock(dispatcher):
            return unlocked(sig)

    dispatcher.compile = compile
    dispatcher._compiles_locked = True
    return dispatcher


def compile_for(dispatcher, args):
    """:func:`compile_locked` for the types of ``args``, as a call of ``dispatcher`` with
    them would type them: for a kernel whose signature is only known from its arguments
    (records, ctypes functions, the film's arrays or none), so that two processes of a first
    run (test workers, batch workers) do not both compile it.

    Parameters
    ----------
    dispatcher : numba dispatcher with a disk cache
    args : tuple
        The arguments of the coming call.
    """
    compile_locked(dispatcher, tuple(dispatcher.typeof_pyval(a) for a in args))


@contextlib.contextmanager
def _kernel_lock(dispatcher):
    """Hold the lock file of ``dispatcher`` (in its cache folder) within the block; where
    there is no such lock (no ``fcntl``, no cache folder, a file system that refuses it),
    the block runs without one, and two processes may then compile the kernel twice."""
    cache_path = getattr(dispatcher._cache, "_cache_path", None)
    lock = None
    if fcntl is not None and cache_path is not None:
        name = dispatcher.py_func.__module__ + "." + dispatcher.py_func.__qualname__
        try:
            os.makedirs(cache_path, exist_ok=True)
            lock = open(os.path.join(cache_path, name + ".compiling"), "a")
            fcntl.flock(lock, fcntl.LOCK_EX)
        except OSError:
            if lock is not None:
                lock.close()
            lock = None
    try:
        yield
    finally:
        if lock is not None:
            fcntl.flock(lock, fcntl.LOCK_UN)
            lock.close()


def _in_disk_cache(dispatcher, signature):
    """Whether numba's disk cache holds ``dispatcher`` compiled for ``signature``, for this
    machine (its index, read without loading the machine code)."""
    cache = dispatcher._cache
    if not hasattr(cache, "_cache_file"):  # no disk cache
        return False
    key = cache._index_key(signature, dispatcher.targetctx.codegen())
    return key in cache._cache_file._load_index()


@contextlib.contextmanager
def helper(enabled=True):
    """Within the block, a helper process compiles the kernel groups this process
    prepares and the disk cache lacks (see the module docstring).

    For programs that own their process (the ``rtmesh`` command): the helper is a second
    process, busy on another core.  It starts at once when a group every render prepares
    is not cached (a first run), else when a render first prepares a group that is not,
    and it is stopped when the block ends.

    Parameters
    ----------
    enabled : bool
        False: no helper (the block runs as it would without this).
    """
    global _enabled, _helper
    with _helper_lock:
        nested = _enabled
    if nested:  # an enclosing block runs the helper
        yield
        return
    # without a second core, or a disk cache to hand kernels over, a helper cannot help;
    # a frozen application's executable is not a Python that could run one
    enabled = enabled and not getattr(sys, "frozen", False) and usable_cores() > 1 and all(
        hasattr(dispatcher._cache, "_cache_file") for group in _GROUPS.values() for dispatcher, _ in group.kernels)
    with _helper_lock:
        _enabled = enabled
    if enabled and first_run():
        _announce(None)
    try:
        yield
    finally:
        with _helper_lock:
            process, _helper, _enabled = _helper, None, False
            for group in _GROUPS.values():
                group._prepared = False
        if process is not None:
            _stop(process)


def first_run():
    """Whether the disk cache lacks a kernel group that every render prepares (the scene
    build's): the first render after an install compiles the kernels."""
    return not all(group.cached() for group in _GROUPS.values() if group.every_render)


def _announce(group):
    """Start the helper process if it is not running, and tell it to compile ``group``
    (None: none yet) from its end.

    Returns
    -------
    bool
        Whether a helper runs.
    """
    global _helper
    with _helper_lock:
        if not _enabled:
            return False
        if _helper is None:
            _helper = _start()
            if _helper is None:
                return False
        if group is not None:
            try:
                _helper.stdin.write(f"{group.module}\t{group.name}\n")
                _helper.stdin.flush()
            except OSError:  # the helper has gone: this process compiles alone
                return False
        return True


def helper_command():
    """The command line of the helper process: it reads group lines from its standard input
    until it closes.

    It imports this very copy of rtmesh, first on its path: with ``python -c`` the working
    folder comes first otherwise, and a folder holding another copy (the source tree that
    ``pip install .`` installed from) would give the helper other kernels and another cache.
    (Not ``python -m`` this module either, which would run a second copy of it beside the
    one :mod:`rtmesh.core` imports.)

    Returns
    -------
    list of str
    """
    package_parent = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    code = (f"import sys; sys.path.insert(0, {package_parent!r}); "
            "from rtmesh.core import compile_ahead; compile_ahead._serve(sys.stdin)")
    return [sys.executable, "-c", code]


def _start():
    """The helper process (:func:`helper_command`); None if it cannot be started."""
    try:
        return subprocess.Popen(helper_command(), stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, text=True)
    except OSError as error:
        log.debug("no compile helper: %s", error)
        return None


def _stop(process):
    """End the helper: whatever it is compiling is no longer needed."""
    try:
        process.stdin.close()
    except OSError:
        pass
    process.terminate()
    process.wait()


def _serve(lines):
    """The helper process: compile each group named on a line (its module, a tab, its
    name), from its end."""
    for line in lines:
        module, _, name = line.rstrip("\n").partition("\t")
        importlib.import_module(module)  # declares the group
        _GROUPS[name].compile_backwards()
