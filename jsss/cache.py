"""Where jsss keeps things on disk, and the persistent XLA compilation cache of the console scripts.

Compiling a fit or a render takes 10-20 s on a CPU and is the same work every time a command
starts; JAX can keep the compiled programs on disk. Library code never changes JAX's global
configuration: only the console scripts (``fit-params``, its batch workers, ``jsss-render``)
call :func:`enable_compilation_cache`, before their first computation.

Where: ``$JAX_COMPILATION_CACHE_DIR`` if set (JAX's own variable), else ``xla/`` in the jsss
cache directory (``$JSSS_CACHE_DIR``, else ``$XDG_CACHE_HOME/jsss``, else ``~/.cache/jsss``).
Set ``JSSS_COMPILATION_CACHE=0`` to turn it off.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

__all__ = ["compilation_cache_dir", "default_cache_dir", "enable_compilation_cache"]


def default_cache_dir() -> Path:
    """``$JSSS_CACHE_DIR``, else ``$XDG_CACHE_HOME/jsss``, else ``~/.cache/jsss``."""
    if os.environ.get("JSSS_CACHE_DIR"):
        return Path(os.environ["JSSS_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "jsss"


def compilation_cache_dir() -> Path | None:
    """The directory the console scripts keep compiled programs in, or None when turned off."""
    if os.environ.get("JSSS_COMPILATION_CACHE", "1") == "0":
        return None
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return Path(os.environ["JAX_COMPILATION_CACHE_DIR"])
    return default_cache_dir() / "xla"


def enable_compilation_cache() -> Path | None:
    """Turn on JAX's persistent cache at :func:`compilation_cache_dir` (console scripts only).

    Programs that took over half a second to compile are kept. An unwritable directory gives
    a warning and no cache (the command still runs). Returns the directory, or None.
    """
    import jax

    path = compilation_cache_dir()
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        warnings.warn(f"{path}: cannot keep compiled programs there ({error}); set JAX_COMPILATION_CACHE_DIR "
                      "or JSSS_CACHE_DIR to a writable directory", stacklevel=2)
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    return path
