"""Arrays the renderer keeps between runs: Laplacian spectra (:mod:`.normal_filter`), layered
profiles (:mod:`.profiles`) and environment visibility maps (:mod:`.lighting`). Each is kept on
disk only in a folder a caller names (the console scripts do); this module writes them so that
a reader never meets half a file."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["save_arrays"]


def save_arrays(path, arrays: dict, *, compressed: bool = False) -> None:
    """Write ``arrays`` (name -> array) to the ``.npz`` file ``path`` atomically: into a temporary
    file beside it, then renamed over it. Raises OSError (callers warn and carry on)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
    try:
        with os.fdopen(handle, "wb") as f:
            (np.savez_compressed if compressed else np.savez)(f, **arrays)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
