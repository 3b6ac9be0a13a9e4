"""Compiled programs and Hankel grids kept across processes: :func:`reusable_program` and
:func:`stored_hankel_grid`.

XLA's persistent cache keeps compiled programs but not JAX's *tracing* of the Python that
makes them, which for a fit (optimistix's solvers under ``vmap``) takes 4-6 s of every start.
Functions decorated with :func:`reusable_program` are therefore kept as XLA executables
under ``jsss-programs/`` (the store is :mod:`jsss.stored_programs`,
which the renderer uses too), and the Hankel grid of the fits (3 s of Bessel functions to
build, 0.05 s to read) under ``jsss-grids/`` (:func:`stored_hankel_grid`), in the folder given
to :func:`keep_programs_in`. Library code writes nothing of its own accord: until a caller
names a folder (the console commands do, see :mod:`measure.commands`), programs are traced
and grids built as usual, in memory.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import tempfile
from pathlib import Path

from jsss import stored_programs
from jsss.stored_programs import keep_programs_in

__all__ = ["keep_programs_in", "reusable_program", "stored_hankel_grid"]


def reusable_program(*, static_argnames=()):
    """:func:`jsss.stored_programs.reusable_program` for code that stands on jsss and fitting:
    a stored program's key holds both packages' sources (and its own package's)."""
    return stored_programs.reusable_program(static_argnames=static_argnames, packages=("jsss", "fitting"))


def stored_hankel_grid(**options):
    """:func:`jsss.layers.hankel.hankel_grid` with these options, read from ``jsss-grids/`` in the
    folder given to :func:`keep_programs_in` where an earlier run stored it; built and stored
    otherwise. Without such a folder it is :func:`jsss.layers.hankel.hankel_grid` itself."""
    import jax.numpy as jnp
    import numpy as np

    from jsss.layers import hankel

    if stored_programs.folder() is None:
        return hankel.hankel_grid(**options)
    dtype = np.dtype(options.pop("dtype", None) or jnp.result_type(float))
    # The grid is hankel.py's NumPy/SciPy arithmetic: keyed on that file and those versions only.
    source = hashlib.sha256(Path(hankel.__file__).read_bytes()).hexdigest()
    signature = repr((sorted(options.items()), dtype.name, source, np.__version__,
                      importlib.metadata.version("scipy")))
    path = stored_programs.folder() / "jsss-grids" / f"hankel-{hashlib.sha256(signature.encode()).hexdigest()[:32]}.npz"
    fields = ("r", "k", "forward_matrix", "inverse_matrix")
    try:
        with np.load(path) as stored:
            return hankel.HankelGrid(*(jnp.asarray(stored[name], dtype=dtype) for name in fields))
    except Exception:  # missing or damaged: build it, and store it for the next start
        grid = hankel.hankel_grid(**options, dtype=dtype)
        with tempfile.TemporaryFile() as buffer:
            np.savez(buffer, **{name: np.asarray(getattr(grid, name)) for name in fields})
            buffer.seek(0)
            stored_programs.write_atomically(path, buffer.read())
        return grid
