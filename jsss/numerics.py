"""Numerical building blocks shared by the physics modules.

Square roots whose derivative is finite at zero, checks that only run on concrete
(non-traced) values, dtype handling, and the float32 accuracy warning. Nothing here
changes JAX's global configuration.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "LowPrecisionWarning",
    "append_axes",
    "as_float_array",
    "device_array",
    "format_value",
    "interpolate_rows",
    "is_concrete",
    "safe_sqrt",
    "warn_if_low_precision",
]


class LowPrecisionWarning(UserWarning):
    """A computation was asked for in a dtype that cannot reach its documented accuracy."""


def is_concrete(value) -> bool:
    """True when ``value`` holds numbers now (not a tracer inside jit/vmap/grad)."""
    leaves = jax.tree_util.tree_leaves(value)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def device_array(value) -> jax.Array:
    """A NumPy array or scalar, or a Python number (not a list), as a ``jnp`` array: what ``jnp.asarray``
    gives (a copy, in JAX's canonical dtype, weakly typed for a Python number), without
    compiling a program.

    ``jnp.asarray`` copies through a small compiled program, one per shape and dtype, 13 ms
    each on this project's 2-core machine: 15-70 of them were 0.2-0.7 s of a command's start.
    """
    try:
        return jax.device_put(value, may_alias=False)
    except TypeError:  # a jax without device_put's may_alias
        return jnp.array(value)


_HOST_NUMBERS = (np.ndarray, np.generic, int, float, bool)


def as_float_array(value) -> jax.Array:
    """``value`` as a floating-point ``jnp`` array, keeping a float dtype it already has.

    Python and integer inputs become JAX's default float (float64 under
    ``jax_enable_x64``, float32 otherwise); float32 stays float32.
    """
    value = device_array(value) if isinstance(value, _HOST_NUMBERS) else jnp.asarray(value)
    if jnp.issubdtype(value.dtype, jnp.floating):
        return value
    return value.astype(jnp.result_type(float))


def format_value(value) -> str:
    """A number or array as a user wrote it (``1.3``, ``[nan, 1.3]``), not as a repr.

    Error messages quote the value a user gave; ``Array([nan], dtype=float64)`` names an
    internal type instead.
    """
    try:
        array = np.asarray(value)
        if not np.issubdtype(array.dtype, np.floating):
            array = array.astype(float)
    except (TypeError, ValueError):
        return repr(value)
    # str of a NumPy scalar is its shortest repr in its own dtype (float32 1.3 prints 1.3).
    if array.ndim == 0:
        return str(array[()])
    return "[" + ", ".join(str(x) for x in array.reshape(-1)) + "]"


@jax.custom_jvp
def safe_sqrt(x):
    r"""Square root of ``max(x, 0)`` whose derivative stays finite at ``x = 0``.

    The derivative :math:`1 / (2\sqrt{x})` is evaluated at ``max(x, tiny)`` with
    ``tiny`` the smallest normal number of the dtype. At ``x = 0`` it is therefore a
    large finite number (about 6.7e153 in float64, 4.6e18 in float32) standing in
    for the true ``+inf``; a zero tangent gives an exact zero, never ``0 * inf = nan``.
    """
    return jnp.sqrt(jnp.maximum(x, 0))


@safe_sqrt.defjvp
def _safe_sqrt_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    tiny = jnp.finfo(jnp.result_type(x)).tiny
    return safe_sqrt(x), t / (2 * jnp.sqrt(jnp.maximum(x, tiny)))


def warn_if_low_precision(array, *, what: str, needs: str) -> None:
    """Warn with :class:`LowPrecisionWarning` when ``array`` is below float64.

    Parameters
    ----------
    array : array_like
        The array whose dtype the computation runs in.
    what : str
        The function or quantity, named in the message.
    needs : str
        The documented accuracy that float32 cannot reach, named in the message.
    """
    dtype = jnp.result_type(array)
    if jnp.issubdtype(dtype, jnp.floating) and np.finfo(dtype).bits < 64:
        warnings.warn(
            f"{what} runs in {np.dtype(dtype).name} and cannot reach {needs}; "
            "pass float64 arrays (enable jax_enable_x64) for that accuracy.",
            LowPrecisionWarning,
            stacklevel=3,
        )


def append_axes(x, ndim: int):
    """``x`` reshaped to ``x.shape + (1,) * ndim`` so it broadcasts against channel axes."""
    x = jnp.asarray(x)
    return x.reshape(x.shape + (1,) * ndim)


def interpolate_rows(position, table):
    """Linear interpolation between the rows of ``table`` (shape ``(n,) + T``) at fractional row
    ``position`` (shape ``S``): shape ``S + T``. The grid is uniform, so the row is found by
    arithmetic, not by a search (``jnp.interp``'s search was most of a lookup on CPU); beyond the
    table the end rows extrapolate linearly (clip ``position`` to ``[0, n - 1]`` to hold them)."""
    n = table.shape[0]
    below = jnp.clip(jnp.floor(position), 0, n - 2)
    t = append_axes(position - below, table.ndim - 1)
    below = below.astype(jnp.int32)
    return (1 - t) * table[below] + t * table[below + 1]
