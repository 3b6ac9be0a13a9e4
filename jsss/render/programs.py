"""Compiled frames kept across calls: one program per method and *layout* of the prepared geometry.

A frame is ``method.radiance(params, prepared)``. Compiled with the prepared geometry as
constants, every new camera or light position would be a new program (seconds of XLA compile
for a frame that runs in a fraction of one). Here the geometry's arrays are the program's
arguments instead: :func:`split` takes a prepared geometry apart into its :class:`Layout` --
its types, its scalars and flags, and the shape and dtype of each array -- and the arrays
themselves; :func:`frame` and :func:`stage` compile once per method configuration and layout
(and the parameters' dtypes), so the same scene with a light moved, the camera turned or the
material changed runs the program it ran before.

What stays a constant of the program: Python scalars and flags (the blur schedule, an
image-space disc radius, the camera's focal length, a uniform texel length), 0-d arrays, and
the fields an object names in its ``static_fields`` (arrays its JAX code reads in NumPy, like an
environment's map): changing one of them is another layout.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib

import jax
import numpy as np

from ..stored_programs import stored_program
from .memory import feed

__all__ = ["FRAME_LAYOUTS", "Layout", "fill", "frame", "split", "stage"]

FRAME_LAYOUTS = 32  # programs kept per kind (frame, each timed stage): the most recently used


class _Slot:
    """Where the ``index``-th array of a prepared geometry goes back in."""

    __slots__ = ("index",)

    def __init__(self, index: int):
        self.index = index


class Layout:
    """A prepared geometry without its arrays: hashable, equal to another of the same structure,
    scalars and array shapes and dtypes (:func:`split`)."""

    def __init__(self, template, shapes):
        self.template = template
        h = hashlib.blake2b(digest_size=20)
        feed(h, (_describe(template), shapes))
        self.key = h.hexdigest()

    def __eq__(self, other) -> bool:
        return isinstance(other, Layout) and other.key == self.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __repr__(self) -> str:
        return f"Layout({self.key[:12]})"


def _describe(template):
    """The template as digestible data (a slot as its index)."""
    if isinstance(template, _Slot):
        return ("slot", template.index)
    if isinstance(template, tuple):
        return (type(template).__qualname__,) + tuple(_describe(t) for t in template)
    if isinstance(template, _Rebuild):
        return (template.cls.__qualname__,) + tuple((k, _describe(v)) for k, v in template.fields)
    return template


class _Rebuild:
    """A dataclass or plain object to be rebuilt from its fields (without running ``__init__``)."""

    __slots__ = ("cls", "fields")

    def __init__(self, cls, fields):
        self.cls, self.fields = cls, fields


def _dynamic(value) -> bool:
    return isinstance(value, (np.ndarray, jax.Array)) and np.ndim(value) >= 1


def split(prepared) -> tuple[Layout, tuple]:
    """``(layout, arrays)``: the prepared geometry's arrays (``ndim >= 1``, in a fixed order)
    and everything else; ``fill(layout, arrays)`` puts them back."""
    arrays: list = []
    template = _split(prepared, arrays)
    shapes = tuple((np.dtype(a.dtype).str, tuple(a.shape)) for a in arrays)
    return Layout(template, shapes), tuple(arrays)


def _split(value, arrays: list, static: bool = False):
    if static:
        return np.asarray(value) if isinstance(value, jax.Array) else value
    if _dynamic(value):
        arrays.append(value)
        return _Slot(len(arrays) - 1)
    if isinstance(value, tuple) and hasattr(value, "_fields"):  # a named tuple
        names = getattr(value, "static_fields", ())
        return type(value)._make(_split(v, arrays, n in names) for n, v in zip(value._fields, value))
    if isinstance(value, tuple):
        return tuple(_split(v, arrays) for v in value)
    if isinstance(value, jax.Array):
        return np.asarray(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        names = getattr(value, "static_fields", ())
        return _Rebuild(type(value), tuple((f.name, _split(getattr(value, f.name), arrays, f.name in names))
                                           for f in dataclasses.fields(value)))
    if isinstance(value, (list, dict)):
        raise TypeError(f"a prepared geometry holds tuples, not a {type(value).__name__}.")
    return value  # a scalar, a string, a plain object without arrays (a blur schedule): part of the layout


def fill(layout: Layout, arrays):
    """The prepared geometry of ``layout`` with ``arrays`` (traced ones, under ``jit``) in place."""
    return _fill(layout.template, arrays)


def _fill(template, arrays):
    if isinstance(template, _Slot):
        return arrays[template.index]
    if isinstance(template, tuple) and hasattr(template, "_fields"):
        return type(template)._make(_fill(t, arrays) for t in template)
    if isinstance(template, tuple):
        return tuple(_fill(t, arrays) for t in template)
    if isinstance(template, _Rebuild):
        out = object.__new__(template.cls)
        for name, item in template.fields:
            object.__setattr__(out, name, _fill(item, arrays))
        return out
    return template


@functools.lru_cache(maxsize=FRAME_LAYOUTS)
def frame(method, layout: Layout):
    """The jitted frame ``(params, arrays) -> radiance`` of a method configuration and a layout.

    Kept traced across processes where a caller named a folder (:mod:`jsss.stored_programs`;
    tracing and lowering a frame was 0.3 s of a command's 2.5 s start), keyed on digests of
    the configuration and the layout."""
    h = hashlib.blake2b(digest_size=20)
    feed(h, method)
    program = jax.jit(lambda params, arrays: method.radiance(params, fill(layout, arrays)))
    return stored_program(program, name=f"frame-{type(method).__name__}", identity=(h.hexdigest(), layout.key))


@functools.lru_cache(maxsize=FRAME_LAYOUTS)
def stage(method, layout: Layout, index: int):
    """The jitted ``index``-th stage ``(params, previous, arrays) -> next`` (for timing each pass)."""
    def run(params, previous, arrays):
        return method.stages(fill(layout, arrays))[index][1](params, previous)

    return jax.jit(run)
