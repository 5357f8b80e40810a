"""numba compilation for rtmesh: one disk cache whose freshness covers every kernel module.

numba keeps compiled machine code on disk and reuses it while the *function's own source
file* is unchanged.  A kernel that calls a jitted function of another module would keep
stale machine code after only that other module changed (an upgrade that touches one file,
or a developer's edit).  rtmesh's kernels call each other across modules (a fused stage
calls the packet tracing of :mod:`rtmesh.geometry.embree_packets` and the shading rows of
:mod:`rtmesh.shading.surfaces`), so their cache entries are stamped with one hash of every
module with compiled code (:func:`kernel_modules`) instead: a change to any of them
recompiles all of them, once.

Everything else is numba's own cache: the same directories (the package's
``__pycache__``, else the user's cache directory, or ``NUMBA_CACHE_DIR``), file names and
index format.
"""

import functools
import hashlib
import os
import re

import numba
from numba.core import caching

# the rtmesh package directory
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# what a module with compiled code imports
_COMPILES = re.compile(rb"^(from rtmesh\.core\.compiled import|import numba|from numba)", re.M)


def kernel_modules(package=None):
    """Every module of the package that has compiled code: those that import this module
    or numba, found by reading the sources (so a new light or material module with kernels
    needs no list to be kept).

    Parameters
    ----------
    package : str, optional
        The package directory (default: rtmesh's).

    Returns
    -------
    tuple of str
        Paths relative to the package directory, ``/``-separated, sorted.
    """
    package = package or _PACKAGE
    found = []
    for folder, subfolders, files in os.walk(package):
        subfolders[:] = sorted(d for d in subfolders if d != "__pycache__")
        for name in files:
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                with open(path, "rb") as source:
                    if _COMPILES.search(source.read()):
                        found.append(os.path.relpath(path, package).replace(os.sep, "/"))
    return tuple(sorted(found))


@functools.cache
def package_stamp():
    """SHA-256 of the sources of :func:`kernel_modules` (and their paths), read once per
    process, and of the packet layout the kernels are compiled for
    (the packets' group width, :data:`rtmesh.geometry.embree_packets.GROUP`, a property of
    the CPU: numba's own cache key names the CPU too, but not where ``NUMBA_CPU_NAME`` makes
    it generic)."""
    from rtmesh.core.packet_group import native_group

    digest = hashlib.sha256()
    for name in kernel_modules():
        with open(os.path.join(_PACKAGE, name), "rb") as source:
            digest.update(name.encode() + b"\0" + source.read())
    digest.update(b"packet group %d" % native_group())
    return digest.digest()


class _PackageStamp:
    """Locator mix-in: the freshness of a cached kernel is that of every kernel module."""

    def get_source_stamp(self):
        return package_stamp()


class _UserProvidedLocator(_PackageStamp, caching.UserProvidedCacheLocator):
    pass


class _InTreeLocator(_PackageStamp, caching.InTreeCacheLocator):
    pass


class _UserWideLocator(_PackageStamp, caching.UserWideCacheLocator):
    pass


class _PackageCacheImpl(caching.CompileResultCacheImpl):
    _locator_classes = [_UserProvidedLocator, _InTreeLocator, _UserWideLocator]


class _PackageCache(caching.FunctionCache):
    _impl_class = _PackageCacheImpl


def _with_package_cache(dispatcher):
    """Give a jitted function the package-stamped disk cache, or none where no cache
    directory is writable (a read-only install with a read-only home): it then compiles
    on every run instead of failing at import."""
    try:
        # what Dispatcher.enable_caching() does, with the package's cache class
        dispatcher._cache = _PackageCache(dispatcher.py_func)
    except RuntimeError:
        pass
    return dispatcher


def kernel(function):
    """Compile ``function`` as an rtmesh kernel: nopython, without the GIL, cached.

    * ``nogil``: chunk threads run kernels side by side, like Embree's queries;
    * ``error_model="numpy"``: a division by zero gives inf or NaN as in NumPy, never an
      exception;
    * no ``fastmath``: no reassociation or fused multiply-adds, so each formula rounds as
      written, the same on every machine and for every chunk and thread count;
    * every compile holds the kernel's lock file
      (:func:`rtmesh.core.compile_ahead.lock_compiles`), so that the processes of a first
      run compile it once between them;
    * no C wrapper (``no_cfunc_wrapper``): kernels are called from Python and from other
      kernels, never through a C function pointer, and numba's wrapper for that costs about
      5 % of a first compile (with the rows' own, below).
    """
    return _kernel(function)


def stage(function):
    """Compile ``function`` as a :func:`kernel` that only other kernels call, through its
    address (:func:`entry_point`, :func:`call_at`): without the wrapper numba builds for
    calls from Python either, about 2 s of the first compile of each of the path kernel's
    stages (their arguments are tuples of dozens of arrays, each unboxed by the
    CPython wrapper)."""
    return _kernel(function, no_cpython_wrapper=True)


def _kernel(function, **options):
    """:func:`kernel` with more numba options."""
    from rtmesh.core.compile_ahead import lock_compiles

    return lock_compiles(_with_package_cache(numba.njit(nogil=True, error_model="numpy", no_cfunc_wrapper=True,
                                                        **options)(function)))


def fix_signatures(dispatcher, signatures):
    """Compile ``dispatcher`` for exactly these signatures (from the disk cache where it
    holds them) and for no others.

    A kernel called with arrays of several layouts (C, Fortran, strided, broadcast) or
    dtypes is otherwise compiled once for each combination met, each costing a second or
    more on the first run; with signatures of any-layout arrays, every call converts to one
    of them instead.  Callers must pass arguments those signatures accept.

    Parameters
    ----------
    dispatcher : numba dispatcher
        A :func:`kernel`.
    signatures : sequence of tuples of numba types
    """
    for signature in signatures:
        dispatcher.compile(tuple(signature))
    dispatcher.disable_compile()


def by_component(vectors):
    """The (3, n) transpose of (n, 3) vectors, as kernels that take vectors by component
    want them.

    rtmesh keeps batches of vectors component-major: (n, 3) arrays laid out as (3, n) in
    memory (NumPy's F order).  numba compiles a kernel once for each array layout it is
    called with, and NumPy marks a (1, 3) array both C- and F-contiguous, so numba types a
    batch of one row as C order: a kernel taking such (n, 3) arrays compiled a second time,
    0.2-1.3 s each, when the tail of a wavefront held one ray (scenes with reflections).
    The transpose of a component-major batch is C order for every n, one included; the
    kernels take it and transpose it back (free in compiled code).

    Parameters
    ----------
    vectors : (n, 3) array

    Returns
    -------
    (3, n) array
        A view.
    """
    return vectors.T


def row(function):
    """Compile ``function`` as a one-row helper of kernels: like :func:`kernel`, but
    callable only from compiled code (no CPython wrapper) and not cached by itself (the
    kernels that call it are cached with it inlined), which saves compile time on the
    first run, and without numba's C wrapper (see :func:`kernel`).  Calls with constant
    arguments share the compile of their types (:func:`_typed_by_types`)."""
    return _typed_by_types(numba.njit(nogil=True, error_model="numpy", no_cpython_wrapper=True,
                                      no_cfunc_wrapper=True)(function))


def _typed_by_types(dispatcher):
    """Make compiled callers of ``dispatcher`` compile it for their arguments' types, not
    for the constants they pass.

    numba types a constant argument as its value (``Literal[int](17)``) and compiles the
    callee once for each constant it is called with: a row called with 15 word offsets
    compiled 15 times, and a first run spent about 10 s of CPU on such copies.  The callee
    is now compiled for the plain types (a caller's constant converts to them, and LLVM
    still folds it where it inlines the row); only a row that cannot be typed without the
    constant (a tuple indexed by an argument) gets numba's literal compile.
    """
    from numba.core import errors, types

    by_value = dispatcher.get_call_template

    def get_call_template(args, kws):
        plain = tuple(types.unliteral(a) for a in args)
        if plain != tuple(args) and not kws:
            try:
                return by_value(plain, kws)
            except errors.TypingError:
                pass  # it needs the constant's value
        return by_value(args, kws)

    dispatcher.get_call_template = get_call_template
    return dispatcher


def inline_row(function):
    """Compile ``function`` as a :func:`row` that LLVM inlines into every caller: its
    machine-code function carries LLVM's ``alwaysinline`` attribute (:func:`_inlined_by_llvm`).

    LLVM inlines only small rows by its own measure; a loop that calls a larger one stays a
    scalar loop with a call per iteration, which passes every argument through the stack
    (a record, a tuple of arrays, is seven words an array) and may take and release a
    reference to each array argument (atomic instructions).  For rows called per sample or
    per lane in the kernels' loops (see :mod:`rtmesh.rendering.direct_stage` and
    :mod:`rtmesh.rendering.path_surfaces`).

    Like any row, it is typed and compiled once per signature in a process, and inlined
    where a caller's module is optimised with it (numba links a callee's module into its
    caller's and optimises the two together).  numba's own inlining (``inline="always"``),
    which rtmesh used before, copies the row's untyped code into each call site and types
    it again there, nested rows in every copy of the rows that call them: the path and
    photon kernels' stages compiled in 89-97 s of CPU that way and in 53-55 s this way,
    their images bit-identical and their renders as fast (docs/BENCHMARKS.md, "Session 26").
    """
    return _inlined_by_llvm(row(function))


def _inlined_by_llvm(dispatcher):
    """Mark every compile of ``dispatcher`` ``alwaysinline`` in the module numba links into
    its callers (``CodeLibrary._get_module_for_linking``, which numba builds once per compile
    and keeps), as each compile is added, before any caller links it.  A numba without that
    method leaves the row a plain row (called where LLVM does not inline it: slower, the
    same results; ``tests/core/test_compiled.py`` notices)."""
    add_overload = dispatcher.add_overload

    def add_inlined_overload(cres):
        linking = getattr(cres.library, "_get_module_for_linking", None)
        if linking is not None:
            linking().get_function(cres.fndesc.llvm_func_name).add_function_attribute("alwaysinline")
        add_overload(cres)

    dispatcher.add_overload = add_inlined_overload
    return dispatcher


def cached(compiler):
    """Apply a numba decorator with ``cache=True``, or without it where no cache directory
    is writable (the ufunc builder's own cache, for :func:`numba.vectorize`: a ufunc calls
    no other kernel, so its own file's stamp is the right one).

    Parameters
    ----------
    compiler : callable
        ``compiler(cache=...)`` returns a numba decorator.

    Returns
    -------
    callable
        A decorator.
    """
    def decorate(function):
        try:
            return compiler(cache=True)(function)
        except RuntimeError:
            return compiler(cache=False)(function)

    return decorate


def _borrow(context, builder, typ, value):
    """``value`` of numba type ``typ`` with every array in it (nested tuples included)
    rebuilt without its memory owner (see :func:`borrowed`)."""
    from numba.core import cgutils, types

    if isinstance(typ, types.Array):
        source = context.make_array(typ)(context, builder, value=value)
        view = context.make_array(typ)(context, builder)
        for field in ("data", "shape", "strides", "itemsize", "nitems"):
            setattr(view, field, getattr(source, field))
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()
    if isinstance(typ, types.BaseTuple):
        items = [_borrow(context, builder, t, builder.extract_value(value, i)) for i, t in enumerate(typ.types)]
        return context.make_tuple(builder, typ, items)
    return value


@numba.extending.intrinsic
def borrowed(typingctx, value):
    """``value`` (an array, a number, or a tuple of them, nested) with its arrays as views
    that own nothing: no reference count is kept for them.

    numba counts references to an array wherever compiled code binds it to a variable: every
    argument of a row, every tuple of arrays (a kernel's records) unpacked or passed on,
    each an atomic increment and decrement of its memory owner's count.  In the path
    kernel's per-lane code those counts took half the render's time (``perf``: ``NRT_incref``
    and ``NRT_decref``).  A kernel reads its inputs, and its own scratch arrays, through
    borrowed views instead: the counting calls find no owner and return at once.  The owners
    must outlive the views: a kernel's arguments do (its caller holds them), and an array it
    allocates itself must stay bound to a variable used after the last use of its views
    (:func:`keep_alive`).
    """
    def codegen(context, builder, signature, args):
        return _borrow(context, builder, signature.args[0], args[0])

    return value(value), codegen


@numba.extending.intrinsic
def keep_alive(typingctx, value):
    """Nothing, but a use of ``value``: an array owning the memory of :func:`borrowed` views
    stays alive (numba releases a variable after its last use) until this point."""
    from numba.core import types

    def codegen(context, builder, signature, args):
        return context.get_dummy_value()

    return types.none(value), codegen


def signature_token(argument_types):
    """A 63-bit number naming a kernel signature (numba types), the same in every process:
    what :func:`call_at` checks a kernel address against."""
    text = "|".join(str(t) for t in argument_types)
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little") >> 1


@numba.extending.intrinsic
def call_at(typingctx, address, token, arguments):
    """Call the kernel compiled at ``address`` with the tuple ``arguments`` (its arguments,
    in order) and return True, if ``token`` is the :func:`signature_token` of their types;
    otherwise call nothing and return False.

    A kernel that calls another the usual way compiles with it: numba links the callee's
    module into the caller's and optimises the whole again, and the caller's first compile
    waits for the callee's.  Called through its address (:func:`entry_point`), the callee is
    compiled and cached on its own, in parallel with its caller on a first run, and the
    caller's compile does not see its code.  The token keeps a wrong address (a kernel
    compiled for other types) from being called: the caller reports it instead.

    Parameters
    ----------
    address, token : int64
        From :func:`entry_point` for the callee and the types of ``arguments``.
    arguments : tuple
    """
    from llvmlite import ir
    from numba.core import cgutils, types

    argument_types = tuple(arguments.types)
    expected = signature_token(argument_types)

    def codegen(context, builder, signature, args):
        address_value, token_value, packed = args
        items = [builder.extract_value(packed, i) for i in range(len(argument_types))]
        function_type = context.call_conv.get_function_type(types.none, argument_types)
        matches = builder.icmp_signed("==", token_value, ir.Constant(token_value.type, expected))
        with builder.if_then(matches):
            callee = builder.inttoptr(address_value, ir.PointerType(function_type))
            status, _ = context.call_conv.call_function(builder, callee, types.none, argument_types, items)
            with cgutils.if_unlikely(builder, status.is_error):
                context.call_conv.return_status_propagate(builder, status)
        return matches

    return types.boolean(types.int64, types.int64, arguments), codegen


def entry_point(dispatcher, signature):
    """The machine-code address of ``dispatcher`` compiled for ``signature`` (compiled, or
    loaded from the disk cache, now) and that signature's token: what :func:`call_at`
    takes.  The dispatcher keeps the code alive.

    Returns
    -------
    address, token : int
    """
    signature = tuple(signature)
    dispatcher.compile(signature)
    result = dispatcher.overloads[signature]
    return result.library.get_pointer_to_function(result.fndesc.llvm_func_name), signature_token(signature)
