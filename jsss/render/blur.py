r"""Separable, hierarchical Gaussian blurs of textures (d'Eon 2007 sec. 5).

One blur step convolves a texture with a Gaussian of variance :math:`\Delta v` [mm^2] on the
surface: a horizontal then a vertical pass of ``taps`` samples (d'Eon's 7) whose spacing in
texels is scaled per texel by the stretch map. Blurs are chained: the texture for
variance :math:`v_i` is the one for :math:`v_{i-1}` blurred by :math:`v_i - v_{i-1}`
(Gaussians add variances under convolution, eq. 11).

Two details make the result match the requested Gaussian rather than roughly so:

* **Exact second moment.** A tap at a fractional offset :math:`x = n + f` texels is read
  by linear interpolation, which spreads it over two texels and adds variance
  :math:`f(1-f)`; together :math:`x^2 + f(1-f) = n^2 + (2n+1)f`, the piecewise-linear
  interpolant of :math:`x^2`. The kernel's variance is therefore piecewise linear and
  increasing in the spacing, and a table at its breakpoints inverts it exactly: the
  spacing is chosen so that the *texture's* variance grows by exactly :math:`\Delta v`.
* **Small steps.** A sparse kernel on a sharp input aliases. A step is split so that no
  variance grows by more than ``max_ratio`` (4, as d'Eon advises), and the chain starts
  at one texel squared, where the kernel's taps are at most a texel apart.

Texels outside the mask get no weight (normalised convolution): a blur neither darkens
at chart borders nor pulls light across the gutter. ``u`` wraps around when the texture
is periodic (a sphere's longitude).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..numerics import is_concrete

__all__ = ["BlurSchedule", "blur_schedule", "blur_step", "hierarchical_blur", "kernel", "spacing_for_variance",
           "uniform_stretch"]


def kernel(taps: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Tap offsets (in units of the spacing) and weights; the end taps sit at 3 standard deviations.

    ``taps = 7`` gives d'Eon's kernel, weights proportional to :math:`e^{-k^2/2}`, k = -3..3.
    """
    if taps < 3 or taps % 2 == 0:
        raise ValueError(f"taps must be an odd number >= 3; got {taps}.")
    half = (taps - 1) // 2
    k = np.arange(-half, half + 1, dtype=float)
    w = np.exp(-0.5 * (3.0 * k / half) ** 2)
    return k, w / w.sum()


@functools.lru_cache(maxsize=32)
def _variance_table(taps: int, max_spacing: int) -> tuple[np.ndarray, np.ndarray]:
    """Spacing s and the kernel's exact variance (texels^2) at every breakpoint up to ``max_spacing``."""
    k, w = kernel(taps)
    half = int(k.max())
    s = np.unique(np.concatenate([np.arange(0, max_spacing * m + 1) / m for m in range(1, half + 1)]))
    x = np.abs(k)[None, :] * s[:, None]
    n = np.floor(x)
    variance = (w[None, :] * (n**2 + (2 * n + 1) * (x - n))).sum(1)
    return s, variance


def spacing_for_variance(variance, *, taps: int = 7, max_spacing: int = 1024):
    """Tap spacing [texels] whose interpolated kernel has exactly ``variance`` [texels^2].

    Variances beyond the table's end are clamped to ``max_spacing``.
    """
    s, v = _variance_table(int(taps), int(max_spacing))
    variance = jnp.asarray(variance)
    return jnp.interp(variance, jnp.asarray(v, variance.dtype), jnp.asarray(s, variance.dtype))


def _lerp_along(values, positions, axis: int, wrap: bool):
    """Linear interpolation of ``values`` (H, W, C) at fractional ``positions`` (H, W) along ``axis``.

    Reads are one flat row gather each (``take_along_axis`` here compiles to a gather per
    channel and slice, an order of magnitude slower on CPU).
    """
    H, W, C = values.shape
    n = values.shape[axis]
    i0 = jnp.floor(positions)
    f = (positions - i0)[..., None]
    i0 = i0.astype(jnp.int32)
    i1 = i0 + 1
    if wrap:
        i0, i1 = i0 % n, i1 % n
        inside0 = inside1 = 1.0
    else:
        inside0 = ((i0 >= 0) & (i0 < n))[..., None].astype(values.dtype)
        inside1 = ((i1 >= 0) & (i1 < n))[..., None].astype(values.dtype)
        i0, i1 = jnp.clip(i0, 0, n - 1), jnp.clip(i1, 0, n - 1)
    flat = values.reshape(H * W, C)
    if axis == 1:
        rows = jnp.arange(H, dtype=jnp.int32)[:, None] * W
        v0, v1 = flat[rows + i0], flat[rows + i1]
    else:
        cols = jnp.arange(W, dtype=jnp.int32)[None, :]
        v0, v1 = flat[i0 * W + cols], flat[i1 * W + cols]
    return (1 - f) * v0 * inside0 + f * v1 * inside1


def _shifted_lerp(values, axis: int, wrap: bool):
    """For one offset shared by every texel: ``read(x)`` is ``values`` (H, W, C) linearly
    interpolated at ``i + x`` along ``axis`` (x a traced scalar), its two reads slices at a
    traced start (``dynamic_slice``) instead of :func:`_lerp_along`'s per-texel gathers, with
    the same integer part and fraction (and zeros, or the period, beyond the edge)."""
    n = values.shape[axis]
    if wrap:  # periodic: read from two copies side by side
        source = jnp.concatenate([values, values], axis=axis)
    else:  # zeros beyond the edge; a shift of n or more lands wholly in the padding
        pad = [(0, 0)] * 3
        pad[axis] = (n + 1, n + 1)
        source = jnp.pad(values, pad)

    def shifted(offset):  # out[i] = values[i + offset] along axis
        start = jnp.mod(offset, n) if wrap else jnp.clip(offset, -(n + 1), n + 1) + n + 1
        starts = [jnp.int32(0)] * 3
        starts[axis] = start.astype(jnp.int32)
        return jax.lax.dynamic_slice(source, starts, values.shape)

    def read(x):
        i0 = jnp.floor(x)
        f = x - i0
        i0 = i0.astype(jnp.int32)
        return (1 - f) * shifted(i0) + f * shifted(i0 + 1)

    return read


def _blur_pass(texture, mask, spacing, axis: int, taps: int, wrap: bool):
    """One normalised 1D pass. ``spacing`` per texel (H, W) reads each tap by gathers; one
    scalar spacing for every texel (a uniform stretch) reads it by shifted slices."""
    offsets, weights = kernel(taps)
    stacked = jnp.concatenate([texture * mask[..., None], mask[..., None]], axis=-1)
    if jnp.ndim(spacing) == 0:
        read = _shifted_lerp(stacked, axis, wrap)
        taps_read = [read(float(k) * spacing) for k in offsets]
    else:
        index = jnp.arange(texture.shape[axis], dtype=spacing.dtype)
        base = index[:, None] if axis == 0 else index[None, :]
        taps_read = [_lerp_along(stacked, base + float(k) * spacing, axis, wrap) for k in offsets]
    total = 0.0
    for w, tap in zip(weights, taps_read):
        total = total + float(w) * tap
    numerator, weight = total[..., :-1], total[..., -1:]
    has = weight > 1e-12
    return jnp.where(has, numerator / jnp.where(has, weight, 1.0), 0.0) * mask[..., None]


def blur_step(texture, mask, stretch, variance, *, taps: int = 7, wrap_u: bool = False):
    """Blur ``texture`` (H, W, C) by a Gaussian of ``variance`` [mm^2] on the surface.

    Parameters
    ----------
    texture : array, shape (H, W, C)
    mask : array, shape (H, W)
        1 on valid texels, 0 elsewhere.
    stretch : array, shape (H, W, 2) or (2,)
        World length of one texel step along u and v [mm]. One pair for every texel (shape
        (2,), a plane) reads each tap as a shifted slice instead of the per-texel gathers a
        varying stretch needs, with the same result (a step on 768^2 x 3 on 2 CPU cores: 213
        against 345 ms).
    variance : scalar [mm^2]
    """
    dtype = texture.dtype
    mask = jnp.asarray(mask, dtype)
    stretch = jnp.asarray(stretch, dtype)
    if stretch.shape == (2,):
        spacing = spacing_for_variance(variance / stretch**2, taps=taps, max_spacing=max(texture.shape[:2]))
        out = _blur_pass(texture, mask, spacing[0], 1, taps, wrap_u)
        return _blur_pass(out, mask, spacing[1], 0, taps, False)
    stretch = jnp.broadcast_to(stretch, mask.shape + (2,))
    safe = jnp.where(stretch > 0, stretch, 1.0)
    size = max(texture.shape[:2])
    spacing = spacing_for_variance(variance / safe**2, taps=taps, max_spacing=size)
    # Materialise the spacing: otherwise XLA fuses the table search into every tap's gather.
    spacing = jax.lax.optimization_barrier(jnp.where(stretch > 0, spacing, 0.0))
    out = _blur_pass(texture, mask, spacing[..., 0], 1, taps, wrap_u)
    # ... and the first pass's result, which XLA would otherwise recompute inside each gather of the second.
    out = jax.lax.optimization_barrier(out)
    return _blur_pass(out, mask, spacing[..., 1], 0, taps, False)


class BlurSchedule:
    """The static shape of a chain of blurs: how many sub-steps lead to each output variance.

    Built from concrete variances by :func:`blur_schedule`; the variances themselves may
    then be traced (differentiated) as long as their order stays the same.
    """

    def __init__(self, substeps: tuple[int, ...], first_variance_ratio: float):
        self.substeps = tuple(int(m) for m in substeps)
        self.first_variance_ratio = float(first_variance_ratio)

    @property
    def n_steps(self) -> int:
        return sum(self.substeps)

    def __repr__(self) -> str:
        return f"BlurSchedule(substeps={self.substeps})"


def blur_schedule(variances, texel_size: float, *, max_ratio: float = 4.0) -> BlurSchedule:
    """Sub-steps per output so that no step more than ``max_ratio``-folds the variance.

    The chain starts at ``texel_size**2`` (or the first variance if it is smaller).
    """
    v = np.asarray(variances, float)
    if v.ndim != 1 or len(v) == 0 or np.any(np.diff(v) <= 0) or v[0] <= 0:
        raise ValueError(f"blur variances must be positive and strictly increasing; got {v.tolist()}.")
    start = min(v[0], texel_size**2)
    previous = [start] + list(v[:-1])
    subs = [max(1, math.ceil(math.log(v[0] / start) / math.log(max_ratio)) + 1)]
    subs += [max(1, math.ceil(math.log(b / a) / math.log(max_ratio) - 1e-9)) for a, b in zip(previous[1:], v[1:])]
    return BlurSchedule(tuple(subs), start / v[0])


def _targets(variances, substeps, first_variance_ratio):
    """Every sub-step's cumulative variance (geometric between outputs); traced-friendly."""
    targets, outputs = [], []
    for i, m in enumerate(substeps):
        hi = variances[i]
        lo = hi * first_variance_ratio if i == 0 else variances[i - 1]
        for j in range(m):
            if i == 0:
                targets.append(lo * (hi / lo) ** (j / max(m - 1, 1)) if m > 1 else hi)
            else:
                targets.append(lo * (hi / lo) ** ((j + 1) / m))
        outputs.append(len(targets) - 1)
    return targets, outputs


def hierarchical_blur(texture, mask, stretch, variances, schedule: BlurSchedule, *, taps: int = 7,
                      wrap_u: bool = False):
    """Textures blurred to each of ``variances`` [mm^2], each from the one before.

    The steps run under one ``lax.scan`` (one compiled step, whatever the chain length).

    Returns
    -------
    array, shape (n, H, W, C)
    """
    ratio = jnp.asarray(schedule.first_variance_ratio, texture.dtype)
    return _chain(texture, mask, uniform_stretch(stretch, mask), variances, ratio, substeps=schedule.substeps,
                  taps=taps, wrap_u=wrap_u)


def uniform_stretch(stretch, mask):
    """``stretch`` as one NumPy (2,) pair where it is the same on every valid texel (a plane; what
    invalid texels hold does not matter, they neither give nor receive light), else as it is.
    Only concrete stretch maps are looked at (geometry is fixed, also during a fit)."""
    if not is_concrete((stretch, mask)):
        return stretch
    values = np.asarray(stretch, float)
    if values.shape == (2,):
        return stretch
    valid = np.broadcast_to(np.asarray(mask) > 0, values.shape[:-1])
    inside = values[valid]
    if inside.size and np.all(inside > 0) and np.all(inside == inside[0]):
        return np.broadcast_to(inside[0], (2,)).astype(np.asarray(stretch).dtype)  # (..., 1): isotropic
    return stretch


@functools.partial(jax.jit, static_argnames=("substeps", "taps", "wrap_u"))
def _chain(texture, mask, stretch, variances, first_variance_ratio, *, substeps, taps, wrap_u):
    # Jitted on its own with the arrays as arguments: one compiled chain per texture size and
    # schedule shape, reused by every frame and fit (a closure would bake the texture in).
    targets, outputs = _targets(variances, substeps, first_variance_ratio)
    targets = jnp.stack([jnp.asarray(t, texture.dtype) for t in targets])
    steps = jnp.diff(targets, prepend=jnp.zeros((1,), texture.dtype))

    def step(current, delta):
        blurred = blur_step(current, mask, stretch, delta, taps=taps, wrap_u=wrap_u)
        return blurred, blurred

    _, every = jax.lax.scan(step, texture, steps)
    return every[jnp.asarray(outputs)]
