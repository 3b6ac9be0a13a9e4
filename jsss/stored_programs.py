"""Compiled programs kept across processes: :func:`reusable_program` and :func:`stored_program`.

XLA's persistent cache keeps compiled programs but not JAX's *tracing* of the Python that
makes them, nor its lowering: for a fit (optimistix's solvers under ``vmap``) 4-6 s of every
start, for a render's frame, profile choice and Gaussian weights 0.5-1 s. Programs made
through this module are therefore kept as XLA's compiled executables
(``jax.experimental.serialize_executable``) under ``jsss-programs/`` in the folder given to
:func:`keep_programs_in`; a start loads them without tracing, lowering or the compilation
cache's lookup. Library code writes nothing of its own accord:
until a caller names a folder (the console commands do, see :mod:`measure.commands`),
programs are traced as usual, in memory. (``fitting.programs`` re-exports this for the fits,
with the Hankel grids beside it.)
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.metadata
import os
import pickle
import platform
import tempfile
import threading
import warnings
from pathlib import Path

__all__ = ["folder", "forget_loaded_programs", "keep_programs_in", "reusable_program", "stored_program"]

# The folder given to keep_programs_in; None (library default) traces as usual.
_folder: Path | None = None


def keep_programs_in(where) -> None:
    """Keep compiled programs under ``where/jsss-programs/`` from now on (console commands; None:
    in memory only, the default).

    The folder is made when the first file is written; one that cannot be written costs a
    trace and a compile per start and a warning, nothing else.
    """
    global _folder
    _folder = None if where is None else Path(where)


def forget_loaded_programs() -> None:
    """Let go of the programs this process loaded or compiled through this module (the next
    call loads them from their files again): each XLA executable holds memory maps of its own,
    of which a Linux process may have 65530
    (for long-lived processes: a batch of many image sizes, the test suite's workers)."""
    _loaded.clear()


def folder() -> Path | None:
    """The folder given to :func:`keep_programs_in`, or None."""
    return _folder


def reusable_program(*, static_argnames=(), packages=("jsss",)):
    """Decorate a jitted function so console scripts reuse its compiled program across processes.

    Library behaviour is unchanged: until :func:`keep_programs_in` has named a folder, or when
    any argument is a tracer (the call is inside ``jit``, ``vmap`` or ``grad``), the function
    is called as it is. Otherwise the call's arrays are flattened, and the program for their
    shapes and dtypes, the pytree structure and the static arguments (``static_argnames``,
    keyword-only) is loaded from disk, or traced, compiled and stored once (atomically).

    The key also holds the versions of jax, jaxlib, equinox, lineax and optimistix, the
    backend, the float64 flag, the processor (an executable is compiled for its instruction
    set) and a hash of the sources and data files (``.npz``, ``.json``) of ``packages`` and of
    the function's own package, so a stored program is never run by code, with tables, or on a
    machine, other than the one that compiled it.
    A file that fails to load, or whose first run fails, is compiled again and replaced.
    """

    def decorate(function):
        identity = (function.__module__, function.__qualname__)
        owners = tuple(dict.fromkeys(tuple(packages) + (function.__module__.split(".")[0],)))

        @functools.wraps(function)
        def wrapper(*args, **kwargs):
            if _folder is None:
                return function(*args, **kwargs)
            static = {name: kwargs.pop(name) for name in static_argnames if name in kwargs}
            return _call(function, function.__name__, identity + (sorted(static.items()),), owners, args, kwargs,
                         static)

        return wrapper

    return decorate


def stored_program(function, *, name: str, identity, packages=("jsss",)):
    """``function`` (jitted, closing over what ``identity`` describes) kept compiled like a
    :func:`reusable_program`.

    For programs made at run time, such as a render's frame for one method configuration and
    geometry layout: ``identity`` (a string or tuple of strings, stable across processes: a
    digest, not an ``id``) stands for what the closure holds, ``name`` names its file.
    """

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        if _folder is None:
            return function(*args, **kwargs)
        return _call(function, name, (name, identity), tuple(packages), args, kwargs, {})

    if hasattr(function, "_cache_size"):  # the jitted function's own count of traces (tests read it)
        wrapper._cache_size = function._cache_size
    return wrapper


_loaded: dict = {}  # key -> (compiled program, output tree structure), for the life of the process


def _call(function, name, identity, packages, args, kwargs, static):
    import jax

    from .numerics import device_array

    leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves) or _elsewhere(leaves):
        return function(*args, **kwargs, **static)
    leaves = [leaf if isinstance(leaf, jax.Array) else device_array(leaf) for leaf in leaves]
    signature = repr((identity, str(treedef), [(leaf.shape, leaf.dtype.name, leaf.weak_type) for leaf in leaves],
                      _fingerprint(packages)))
    key = hashlib.sha256(signature.encode()).hexdigest()[:32]
    path = _folder / "jsss-programs" / f"{name}-{key}.xla"
    if key not in _loaded:
        loaded = _load(path, leaves)
        if loaded is not None:
            program, out_tree = loaded
            try:  # the first run of a loaded executable is checked; see _compile_and_store
                out = jax.block_until_ready(program(*leaves))
            except (jax.errors.JaxRuntimeError, ValueError, TypeError):
                path.unlink(missing_ok=True)
            else:
                _loaded[key] = loaded
                return jax.tree_util.tree_unflatten(out_tree, out)
        with _compiling:  # one store compile at a time: the cache bypass below is process state
            _loaded[key] = _compile_and_store(path, function, static, treedef, leaves)
    program, out_tree = _loaded[key]
    return jax.tree_util.tree_unflatten(out_tree, program(*leaves))


_compiling = threading.Lock()


def _elsewhere(leaves) -> bool:
    """Whether an argument is committed to a device other than the default one: a stored
    executable runs only on the device it was compiled for, so such a call is the plain
    function's."""
    import jax

    default = jax.devices()[0]
    return any(isinstance(leaf, jax.Array) and leaf.committed and leaf.devices() != {default} for leaf in leaves)


# The file: 4 bytes (little-endian length of the header), the header (pickled: the output with
# each leaf replaced by 0, whose tree structure the program's flat output takes, and whether the
# program calls LAPACK), the executable's SHA-256, and the executable.

def _load(path: Path, leaves):
    """(program, output tree structure) from ``path``, or None where it is missing or damaged.

    The executable is XLA's own (``jax.experimental.serialize_executable``): loading it skips
    tracing, lowering and the compilation cache's lookup, which hashes the lowered module.
    Through ``jax.export`` (until 2026-12-05) each load was lowered again: 0.27 s of a marble
    render's 2.5 s start. The SHA-256 guards against a damaged file, which deserializing could crash
    on; LAPACK's kernels are loaded into jaxlib only while lowering (importing SciPy's, 0.35 s),
    so a program that calls them loads them first, or it would crash.
    """
    import jax
    from jax.experimental import serialize_executable

    try:
        data = path.read_bytes()
        size = int.from_bytes(data[:4], "little")
        skeleton, calls_lapack = pickle.loads(data[4:4 + size])
        digest, executable = data[4 + size:36 + size], data[36 + size:]
        if hashlib.sha256(executable).digest() != digest:
            return None
        out_tree = jax.tree_util.tree_structure(skeleton)
        if calls_lapack:
            _initialize_lapack()
        return serialize_executable.deserialize_and_load(
            executable, jax.tree_util.tree_structure((tuple(leaves), {})),
            jax.tree_util.tree_structure([0] * out_tree.num_leaves)), out_tree
    except Exception:  # noqa: BLE001 -- missing, truncated or from an incompatible writer: compile again
        return None


def _compile_and_store(path: Path, function, static, treedef, leaves):
    """Trace, lower and compile ``function`` for ``leaves``' shapes; store the executable.

    XLA's CPU executables cannot be serialized again once they were loaded from a serialized
    form: one that came from the persistent compilation cache is written without some of its
    functions and fails when run ("Function ... not found"). So the compile that is stored
    bypasses that cache where it would hit it; the first run of every loaded program is checked
    as well (:func:`_call`), and a program that fails there is compiled again.
    """
    import jax
    from jax.experimental import serialize_executable

    trees = []

    def flat(*flat_leaves):
        args, kwargs = jax.tree_util.tree_unflatten(treedef, flat_leaves)
        out, tree = jax.tree_util.tree_flatten(function(*args, **kwargs, **static))
        trees.append(tree)
        return out

    specs = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, weak_type=leaf.weak_type) for leaf in leaves]
    lowered = jax.jit(flat).lower(*specs)
    hits = _cache_hits()
    program = lowered.compile()
    out_tree = trees[-1]
    try:  # a program that cannot be stored (a host callback, an option XLA lacks) runs unstored
        if _cache_hits() != hits:
            with _without_compilation_cache():  # an option (XLA's default) that JAX's in-memory cache keys on
                storable = lowered.compile(compiler_options={"xla_cpu_enable_fast_math": False})
        else:
            storable = program
        calls_lapack = "lapack_" in lowered.as_text()
        header = pickle.dumps((jax.tree_util.tree_unflatten(out_tree, [0] * out_tree.num_leaves), calls_lapack))
        executable, _, _ = serialize_executable.serialize(storable)
    except Exception as error:  # noqa: BLE001
        warnings.warn(f"{path.name}: the compiled program is not kept ({type(error).__name__}: {error})",
                      stacklevel=4)
        return program, out_tree
    write_atomically(path, len(header).to_bytes(4, "little") + header + hashlib.sha256(executable).digest()
                     + executable)
    return program, out_tree


_cache_hit_count = 0  # persistent-cache hits in this process, once _cache_hits has registered its listener
_listening = False


def _count_cache_hit(event: str, **_) -> None:
    global _cache_hit_count
    _cache_hit_count += event == "/jax/compilation_cache/cache_hits"


def _cache_hits() -> int:
    """How many compiles in this process XLA's persistent cache served (from the first call on)."""
    global _listening
    if not _listening:
        import jax

        jax.monitoring.register_event_listener(_count_cache_hit)
        _listening = True
    return _cache_hit_count


@contextlib.contextmanager
def _without_compilation_cache():
    """XLA's persistent compilation cache off for one compile (it is read once per process, so
    it is reset on the way in and out)."""
    import jax
    from jax.experimental.compilation_cache import compilation_cache

    enabled = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    compilation_cache.reset_cache()
    try:
        yield
    finally:
        jax.config.update("jax_enable_compilation_cache", enabled)
        compilation_cache.reset_cache()


@functools.cache
def _initialize_lapack() -> None:
    """Load LAPACK's kernels into jaxlib, as lowering a linear-algebra operation does."""
    import jax

    try:
        from jax._src.lax import linalg

        linalg.initialize_lapack()
    except (ImportError, AttributeError):  # a jax without it: lower one Cholesky, which loads them
        jax.jit(jax.numpy.linalg.cholesky).lower(jax.ShapeDtypeStruct((2, 2), "float32"))


def write_atomically(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it; an unwritable folder warns."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as handle:
            handle.write(data)
        os.replace(handle.name, path)
    except OSError as error:  # a read-only cache costs a trace and a compile per start, nothing else
        warnings.warn(f"{path}: cannot keep the compiled program there ({error})", stacklevel=4)


@functools.cache
def _fingerprint(packages: tuple) -> str:
    """Versions, backend and device kind, float64 flag, processor, ``XLA_FLAGS`` and a hash of the
    sources and data files (tables, calibration) whose programs are stored: what a compiled
    executable depends on."""
    import jax

    versions = []
    for name in ("jax", "jaxlib", "equinox", "lineax", "optimistix"):
        try:
            versions.append(f"{name}={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            versions.append(f"{name}=?")
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    for package in packages:
        # The data files too: a program holds the tables it was traced with as constants.
        sources = [path for pattern in ("*.py", "*.npz", "*.json") for path in (root / package).rglob(pattern)]
        for source in sorted(sources):
            digest.update(source.relative_to(root).as_posix().encode())
            digest.update(source.read_bytes())
    device = jax.devices()[0]
    return (f"{' '.join(versions)} {jax.default_backend()} {getattr(device, 'device_kind', '?')} "
            f"x64={jax.config.jax_enable_x64} {_processor()} XLA_FLAGS={os.environ.get('XLA_FLAGS', '')} "
            f"{digest.hexdigest()}")


def _processor() -> str:
    """The CPU's model and instruction-set flags (Linux), or the platform's processor name: an
    XLA CPU executable uses the instructions of the machine that compiled it, and a cache
    folder may be shared between machines."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:
            lines = [line for line in info if line.startswith(("model name", "flags", "Features"))]
        return hashlib.sha256("".join(sorted(set(lines))).encode()).hexdigest()[:16]
    except OSError:
        return f"{platform.machine()} {platform.processor()}"
