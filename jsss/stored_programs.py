"""Traced programs kept across processes: :func:`reusable_program` and :func:`stored_program`.

XLA's persistent cache keeps compiled programs but not JAX's *tracing* of the Python that
makes them: for a fit (optimistix's solvers under ``vmap``) 4-6 s of every start, for a
render's frame, profile choice and Gaussian weights 0.5 s. Programs made through this module
are therefore kept traced, as serialized ``jax.export`` programs under ``jsss-programs/`` in
the folder given to :func:`keep_programs_in`. Library code writes nothing of its own accord:
until a caller names a folder (the console commands do, see :mod:`measure.commands`),
programs are traced as usual, in memory. (``fitting.programs`` re-exports this for the fits,
with the Hankel grids beside it.)
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
import pickle
import re
import tempfile
import warnings
from pathlib import Path

__all__ = ["folder", "keep_programs_in", "reusable_program", "stored_program"]

# The folder given to keep_programs_in; None (library default) traces as usual.
_folder: Path | None = None


def keep_programs_in(where) -> None:
    """Keep traced programs under ``where/jsss-programs/`` from now on (console commands; None:
    in memory only, the default).

    The folder is made when the first file is written; one that cannot be written costs a
    trace per start and a warning, nothing else.
    """
    global _folder
    _folder = None if where is None else Path(where)


def folder() -> Path | None:
    """The folder given to :func:`keep_programs_in`, or None."""
    return _folder


def reusable_program(*, static_argnames=(), packages=("jsss",)):
    """Decorate a jitted function so console scripts reuse its tracing across processes.

    Library behaviour is unchanged: until :func:`keep_programs_in` has named a folder, or when
    any argument is a tracer (the call is inside ``jit``, ``vmap`` or ``grad``), the function
    is called as it is. Otherwise the call's arrays are flattened, and the program for their
    shapes and dtypes, the pytree structure and the static arguments (``static_argnames``,
    keyword-only) is loaded from disk, or traced once with ``jax.export`` and stored
    (atomically). Its compilation then comes from XLA's cache like any other.

    The key also holds the versions of jax, jaxlib, equinox, lineax and optimistix, the
    backend, the float64 flag and a hash of the sources of ``packages`` and of the function's
    own package, so a stored program is never run by code other than the one that traced it.
    That is also why the export's compatibility checks on LAPACK custom calls are off: a
    program is only ever loaded by the exact jaxlib that wrote it. A file that fails to load is
    traced again and replaced.
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
    """``function`` (jitted, closing over what ``identity`` describes) kept traced like a
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


_loaded: dict = {}  # key -> (jax.export.Exported, output tree structure), for the life of the process


def _call(function, name, identity, packages, args, kwargs, static):
    import jax

    leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return function(*args, **kwargs, **static)
    leaves = [jax.numpy.asarray(leaf) for leaf in leaves]
    signature = repr((identity, str(treedef), [(leaf.shape, leaf.dtype.name, leaf.weak_type) for leaf in leaves],
                      _fingerprint(packages)))
    key = hashlib.sha256(signature.encode()).hexdigest()[:32]
    program, out_tree = _loaded.get(key) or _load_or_trace(function, name, static, treedef, leaves, key)
    return jax.tree_util.tree_unflatten(out_tree, program.call(*leaves))


def _load_or_trace(function, name, static, treedef, leaves, key):
    """The stored program and its output's tree structure. The program returns its output's
    leaves: ``jax.export`` serializes only the pytree types it knows, so the structure is kept
    beside it, as a pickled skeleton (the output with each leaf replaced by 0), in one file."""
    import jax
    from jax import export

    path = _folder / "jsss-programs" / f"{name}-{key}.jaxexport"
    try:
        data = path.read_bytes()
        size = int.from_bytes(data[:4], "little")
        out_tree = jax.tree_util.tree_structure(pickle.loads(data[4:4 + size]))
        program = export.deserialize(bytearray(data[4 + size:]))
    except Exception:  # noqa: BLE001 -- missing, truncated or from an incompatible writer: trace again
        trees = []

        def flat(*flat_leaves):
            args, kwargs = jax.tree_util.tree_unflatten(treedef, flat_leaves)
            out, tree = jax.tree_util.tree_flatten(function(*args, **kwargs, **static))
            trees.append(tree)
            return out

        specs = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, weak_type=leaf.weak_type) for leaf in leaves]
        jitted = jax.jit(flat)  # one object: export's own trace and lowering reuse these
        targets = sorted(set(re.findall(r"custom_call @(\w+)", jitted.trace(*specs).lower().as_text())))
        program = export.export(jitted, disabled_checks=[
            export.DisabledSafetyCheck.custom_call(target) for target in targets])(*specs)
        out_tree = trees[-1]
        skeleton = pickle.dumps(jax.tree_util.tree_unflatten(out_tree, [0] * out_tree.num_leaves))
        write_atomically(path, len(skeleton).to_bytes(4, "little") + skeleton + program.serialize())
    _loaded[key] = program, out_tree
    return program, out_tree


def write_atomically(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it; an unwritable folder warns."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as handle:
            handle.write(data)
        os.replace(handle.name, path)
    except OSError as error:  # a read-only cache costs a trace per start, nothing else
        warnings.warn(f"{path}: cannot keep the traced program there ({error})", stacklevel=4)


@functools.cache
def _fingerprint(packages: tuple) -> str:
    """Versions, backend, float64 flag and a hash of the sources whose tracing is stored."""
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
        for source in sorted((root / package).rglob("*.py")):
            digest.update(source.relative_to(root).as_posix().encode())
            digest.update(source.read_bytes())
    return f"{' '.join(versions)} {jax.default_backend()} x64={jax.config.jax_enable_x64} {digest.hexdigest()}"
