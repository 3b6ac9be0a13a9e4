"""Geometry a process keeps between frames: rasters, texels, shadow maps and the lights at them.

Everything a frame's ``prepare`` rasterizes depends on the mesh, the camera, the lights'
positions (or directions, or an environment's map) and a few sizes -- never on the material
or on how bright a light is. An interactive loop (brighter light, other material, render
again) therefore rasterizes once: :func:`kept` remembers each piece under a digest of exactly
those inputs (:func:`mesh_key`, :func:`camera_key`, :func:`light_key`), the most recently used
first, up to :data:`KEPT_BYTES` of arrays. A piece is a pure function of its key, so a kept
one is the one that would be computed again; its arrays are made read-only so that no caller
can change what the next frame reads. :func:`forget` empties the memory (tests, or to free it).

:func:`digest` is the BLAKE2 digest of nested data (arrays, scalars, tuples, dataclasses) that
these keys and :class:`jsss.render.methods.PreparedGeometry`'s equality are built on; a
read-only array's digest is computed once and remembered while the array lives.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import threading
import weakref

import numpy as np

__all__ = ["KEPT_BYTES", "camera_key", "digest", "feed", "forget", "kept", "kept_bytes", "light_key", "mesh_key"]

KEPT_BYTES = 1 << 30  # arrays kept at most [bytes]: a 512^2 texture-space scene with one light holds ~60 MB

_kept: collections.OrderedDict = collections.OrderedDict()  # key -> (value, bytes), least recently used first
_lock = threading.Lock()  # a batch's threads may prepare frames at once
_array_digests: dict = {}  # id(read-only array) -> (weak reference, digest)
_mesh_keys: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_LIGHT_SHADE = ("color", "intensity")  # what a light's colour and brightness are: not geometry


def _array_digest(value: np.ndarray) -> bytes:
    """The digest of an array's dtype, shape and bytes; remembered for a read-only array."""
    frozen = not value.flags.writeable
    if frozen:
        known = _array_digests.get(id(value))
        if known is not None and known[0]() is value:
            return known[1]
    h = hashlib.blake2b(digest_size=20)
    contiguous = np.ascontiguousarray(value)
    h.update(f"array {contiguous.dtype.str} {contiguous.shape};".encode())
    h.update(contiguous.tobytes())
    out = h.digest()
    if frozen:
        key = id(value)
        _array_digests[key] = (weakref.ref(value, lambda _, key=key: _array_digests.pop(key, None)), out)
    return out


def feed(h, value) -> None:
    """Add ``value`` (arrays, scalars, strings, tuples, dataclasses, plain objects, nested) to the digest ``h``."""
    if isinstance(value, np.ndarray):
        h.update(_array_digest(value))
    elif isinstance(value, np.generic):
        h.update(f"{value.dtype.str} {value!r};".encode())
    elif value is None or isinstance(value, (bool, int, float, str, complex)):
        h.update(f"{type(value).__name__} {value!r};".encode())
    elif isinstance(value, (tuple, list)):
        h.update(f"{type(value).__name__} {len(value)}(".encode())
        for item in value:
            feed(h, item)
        h.update(b")")
    elif isinstance(value, dict):
        h.update(f"dict {len(value)}(".encode())
        for name in sorted(value, key=repr):
            feed(h, name)
            feed(h, value[name])
        h.update(b")")
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        h.update(f"{type(value).__qualname__}(".encode())
        for field in dataclasses.fields(value):
            feed(h, getattr(value, field.name))
        h.update(b")")
    elif hasattr(value, "__array__") and hasattr(value, "dtype"):  # a jax.Array
        h.update(_array_digest(np.asarray(value)))
    elif hasattr(value, "__dict__"):
        h.update(f"{type(value).__qualname__}(".encode())
        for name, item in sorted(vars(value).items()):
            h.update(f"{name}=".encode())
            feed(h, item)
        h.update(b")")
    else:
        raise TypeError(f"cannot digest a {type(value).__name__}.")


def digest(*parts) -> str:
    """BLAKE2 digest (hex) of ``parts`` (see :func:`feed`)."""
    h = hashlib.blake2b(digest_size=20)
    feed(h, parts)
    return h.hexdigest()


def mesh_key(mesh) -> str:
    """Digest of everything a raster reads of ``mesh``: vertices, normals, UVs, faces, ``wrap_u``
    and ``has_uvs`` (unlike :meth:`Mesh.digest`, which leaves the normals out); once per mesh."""
    key = _mesh_keys.get(mesh)
    if key is None:
        key = digest("mesh", mesh.vertices, mesh.normals, mesh.uvs, mesh.faces, bool(mesh.wrap_u),
                     bool(getattr(mesh, "has_uvs", True)))
        _mesh_keys[mesh] = key
    return key


def camera_key(camera) -> str:
    """Digest of a view (a frozen dataclass of its position, target, field of view and pixels)."""
    return digest("camera", camera)


def light_key(light) -> str:
    """Digest of a light's geometry: every field but its colour and intensity (its kind, position,
    direction; an environment's map and rotation), which only scale its light."""
    fields = [(f.name, getattr(light, f.name)) for f in dataclasses.fields(light) if f.name not in _LIGHT_SHADE]
    return digest("light", type(light).__qualname__, getattr(light, "kind", None), tuple(fields))


def _arrays(value, seen=None):
    """The NumPy arrays in nested data (each once)."""
    seen = set() if seen is None else seen
    if isinstance(value, np.ndarray):
        if id(value) not in seen:
            seen.add(id(value))
            yield value
    elif isinstance(value, (tuple, list)):
        for item in value:
            yield from _arrays(item, seen)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            yield from _arrays(getattr(value, field.name), seen)
    elif hasattr(value, "__dict__") and not isinstance(value, type):
        for item in vars(value).values():
            yield from _arrays(item, seen)


def kept(kind: str, key, compute):
    """``compute()``, or the value kept for ``(kind, key)`` when there is one.

    ``key`` must hold every input ``compute`` reads (a digest, or a tuple of them and of sizes).
    The value's arrays are made read-only. When the kept arrays pass :data:`KEPT_BYTES`, the
    least recently used values are dropped (never the one just computed).
    """
    full = (kind, key)
    with _lock:
        if full in _kept:
            _kept.move_to_end(full)
            return _kept[full][0]
    value = compute()
    arrays = list(_arrays(value))
    for a in arrays:
        a.flags.writeable = False
    size = sum(a.nbytes for a in arrays)
    with _lock:
        _kept[full] = (value, size)
        _kept.move_to_end(full)
        total = sum(s for _, s in _kept.values())
        while total > KEPT_BYTES and len(_kept) > 1:
            _, (_, dropped) = _kept.popitem(last=False)
            total -= dropped
    return value


def kept_bytes() -> int:
    """Bytes of arrays kept now."""
    with _lock:
        return sum(s for _, s in _kept.values())


def forget() -> None:
    """Drop every kept piece of geometry (the next frame rasterizes again)."""
    with _lock:
        _kept.clear()
