"""Traced programs kept across processes: :func:`reusable_program` and :func:`stored_hankel_grid`.

XLA's persistent cache keeps compiled programs but not JAX's *tracing* of the Python that
makes them, which for a fit (optimistix's solvers under ``vmap``) takes 4-6 s of every start.
Functions decorated with :func:`reusable_program` are therefore kept traced, as serialized
``jax.export`` programs under ``jsss-programs/``, and the Hankel grid of the fits (3 s of
Bessel functions to build, 0.05 s to read) under ``jsss-grids/`` (:func:`stored_hankel_grid`),
in the folder given to :func:`keep_programs_in`. Library code writes nothing of its own
accord: until a caller names a folder (the console commands do, see
:mod:`measure.commands`), programs are traced and grids built as usual, in memory.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
import re
import tempfile
import warnings
from pathlib import Path

__all__ = ["keep_programs_in", "reusable_program", "stored_hankel_grid"]

# The folder given to keep_programs_in; None (library default) traces and builds as usual.
_folder: Path | None = None


def keep_programs_in(folder) -> None:
    """Keep traced programs under ``folder/jsss-programs/`` and Hankel grids under
    ``folder/jsss-grids/`` from now on (console commands; None: in memory only, the default).

    The folders are made when the first file is written; one that cannot be written costs a
    trace per start and a warning, nothing else.
    """
    global _folder
    _folder = None if folder is None else Path(folder)


def reusable_program(*, static_argnames=()):
    """Decorate a jitted function so console scripts reuse its tracing across processes.

    Library behaviour is unchanged: until :func:`keep_programs_in` has named a folder, or when
    any argument is a tracer (the call is inside ``jit``, ``vmap`` or ``grad``), the function
    is called as it is. Otherwise the call's arrays are flattened, and the program for their
    shapes and dtypes, the pytree structure and the static arguments (``static_argnames``,
    keyword-only) is loaded from disk, or traced once with ``jax.export`` and stored
    (atomically). Its compilation then comes from XLA's cache like any other.

    The key also holds the versions of jax, jaxlib, equinox, lineax and optimistix, the
    backend, the float64 flag and a hash of the sources of jsss, fitting and the function's own package, so a stored program
    is never run by code other than the one that traced it. That is also why the export's
    compatibility checks on LAPACK custom calls are off: a program is only ever loaded by the
    exact jaxlib that wrote it. A file that fails to load is traced again and replaced.
    """

    def decorate(function):
        @functools.wraps(function)
        def wrapper(*args, **kwargs):
            import jax

            if _folder is None:
                return function(*args, **kwargs)
            static = {name: kwargs.pop(name) for name in static_argnames if name in kwargs}
            leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
            if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
                return function(*args, **kwargs, **static)
            leaves = [jax.numpy.asarray(leaf) for leaf in leaves]
            signature = repr((function.__module__, function.__qualname__, sorted(static.items()), str(treedef),
                              [(leaf.shape, leaf.dtype.name, leaf.weak_type) for leaf in leaves],
                              _fingerprint(function.__module__.split(".")[0])))
            key = hashlib.sha256(signature.encode()).hexdigest()[:32]
            program = _loaded.get(key) or _load_or_trace(function, static, treedef, leaves, key)
            return program.call(*leaves)

        return wrapper

    return decorate


_loaded: dict = {}  # key -> jax.export.Exported, for the life of the process


def _load_or_trace(function, static, treedef, leaves, key):
    import jax
    from jax import export

    path = _folder / "jsss-programs" / f"{function.__name__}-{key}.jaxexport"
    try:
        program = export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # missing, truncated or from an incompatible writer: trace again
        def flat(*flat_leaves):
            args, kwargs = jax.tree_util.tree_unflatten(treedef, flat_leaves)
            return function(*args, **kwargs, **static)

        specs = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, weak_type=leaf.weak_type) for leaf in leaves]
        jitted = jax.jit(flat)  # one object: export's own trace and lowering reuse these
        targets = sorted(set(re.findall(r"custom_call @(\w+)", jitted.trace(*specs).lower().as_text())))
        program = export.export(jitted, disabled_checks=[
            export.DisabledSafetyCheck.custom_call(target) for target in targets])(*specs)
        _write_atomically(path, program.serialize())
    _loaded[key] = program
    return program


def _write_atomically(path: Path, data: bytes) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as handle:
            handle.write(data)
        os.replace(handle.name, path)
    except OSError as error:  # a read-only cache costs a trace per start, nothing else
        warnings.warn(f"{path}: cannot keep the traced program there ({error})", stacklevel=3)


# The packages below this one (and this one): the sources a program traced from here can run.
_BELOW = ("jsss", "fitting")


@functools.lru_cache(maxsize=None)
def _fingerprint(package: str) -> str:
    """Versions, backend, float64 flag and a hash of the sources whose tracing is stored: the
    packages this module stands on, and the package of the decorated function (``package``,
    which may sit above: ``measure.synth`` keeps programs too)."""
    import jax

    versions = []
    for name in ("jax", "jaxlib", "equinox", "lineax", "optimistix"):
        try:
            versions.append(f"{name}={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            versions.append(f"{name}=?")
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    for name in dict.fromkeys(_BELOW + (package,)):
        for source in sorted((root / name).rglob("*.py")):
            digest.update(source.relative_to(root).as_posix().encode())
            digest.update(source.read_bytes())
    return f"{' '.join(versions)} {jax.default_backend()} x64={jax.config.jax_enable_x64} {digest.hexdigest()}"


def stored_hankel_grid(**options):
    """:func:`jsss.layers.hankel.hankel_grid` with these options, read from ``jsss-grids/`` in the
    folder given to :func:`keep_programs_in` where an earlier run stored it; built and stored
    otherwise. Without such a folder it is :func:`jsss.layers.hankel.hankel_grid` itself."""
    import jax.numpy as jnp
    import numpy as np

    from jsss.layers import hankel

    if _folder is None:
        return hankel.hankel_grid(**options)
    dtype = np.dtype(options.pop("dtype", None) or jnp.result_type(float))
    # The grid is hankel.py's NumPy/SciPy arithmetic: keyed on that file and those versions only.
    source = hashlib.sha256(Path(hankel.__file__).read_bytes()).hexdigest()
    signature = repr((sorted(options.items()), dtype.name, source, np.__version__,
                      importlib.metadata.version("scipy")))
    path = _folder / "jsss-grids" / f"hankel-{hashlib.sha256(signature.encode()).hexdigest()[:32]}.npz"
    fields = ("r", "k", "forward_matrix", "inverse_matrix")
    try:
        with np.load(path) as stored:
            return hankel.HankelGrid(*(jnp.asarray(stored[name], dtype=dtype) for name in fields))
    except Exception:  # missing or damaged: build it, and store it for the next start
        grid = hankel.hankel_grid(**options, dtype=dtype)
        with tempfile.TemporaryFile() as buffer:
            np.savez(buffer, **{name: np.asarray(getattr(grid, name)) for name in fields})
            buffer.seek(0)
            _write_atomically(path, buffer.read())
        return grid
