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
from jax.custom_derivatives import SymbolicZero

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
    """Spacing s and the kernel's exact variance (texels^2) on a grid that holds every breakpoint.

    The breakpoints are where a tap crosses a texel, s = n / |k|, so all lie on multiples of
    1 / lcm(1..half); between grid points the variance is linear in s.
    """
    k, w = kernel(taps)
    half = int(k.max())
    per_texel = math.lcm(*range(1, half + 1))
    s = np.arange(max_spacing * per_texel + 1) / per_texel
    x = np.abs(k)[None, :] * s[:, None]
    n = np.floor(x + 1e-9)  # s = n / |k| exactly: the tap sits on texel n
    variance = (w[None, :] * (n**2 + (2 * n + 1) * np.maximum(x - n, 0.0))).sum(1)
    return s, variance


@functools.lru_cache(maxsize=32)
def _inverse_lookup(taps: int, max_spacing: int):
    """For :func:`spacing_for_variance`: cells uniform in sqrt(variance), each holding at most one
    grid point, and per cell the last grid point at or below the cell's start."""
    s, variance = _variance_table(taps, max_spacing)
    root = np.sqrt(variance)
    cell = 0.5 * float(np.min(np.diff(root)))
    starts = np.arange(int(root[-1] / cell) + 2) * cell
    first = np.clip(np.searchsorted(variance, starts**2, side="right") - 1, 0, len(s) - 2)
    return s, variance, cell, first


def spacing_for_variance(variance, *, taps: int = 7, max_spacing: int = 1024):
    """Tap spacing [texels] whose interpolated kernel has exactly ``variance`` [texels^2].

    Variances beyond the table's end are clamped to ``max_spacing``. The inverse is the
    piecewise-linear interpolant through the breakpoints, found without a search: the cell of
    sqrt(variance) gives the grid point to within one either way, three comparisons settle
    it (``jnp.interp``'s binary search over the 3000 points took a third of a blur step).
    """
    s, v, cell, first = _inverse_lookup(int(taps), int(max_spacing))
    variance = jnp.asarray(variance)
    dtype = variance.dtype
    table = jnp.asarray(v, dtype)
    clamped = jnp.clip(variance, 0.0, float(v[-1]))
    c = jnp.clip(jnp.floor(jnp.sqrt(clamped) / cell).astype(jnp.int32), 0, len(first) - 1)
    lo = jnp.asarray(first, jnp.int32)[c]
    count = sum((clamped >= table[jnp.clip(lo + i, 0, len(v) - 1)]).astype(jnp.int32) for i in range(3))
    j = jnp.clip(lo - 1 + count, 0, len(v) - 2)
    v0, v1 = table[j], table[j + 1]
    step = float(s[1] - s[0])
    fraction = jnp.clip((clamped - v0) / (v1 - v0), 0.0, 1.0)
    return (j.astype(dtype) + fraction) * step


def _gathered_lerp(values, axis: int, wrap: bool):
    """For per-texel positions: ``read(positions)`` is ``values`` (H, W, C) linearly interpolated
    at fractional ``positions`` (H, W) along ``axis`` (zeros, or the period, beyond the edge).

    Along rows (``axis = 1``) the two texels a tap spans are neighbours in memory: one gather
    of a (2, C) window per texel reads both, from ``values`` padded by a column on each side
    (zeros) or by the first column after the last (wrap). Along columns they are a row apart:
    two gathers of C values each. (``take_along_axis`` compiles to a gather per channel and
    slice, an order of magnitude slower on CPU.)
    """
    H, W, C = values.shape
    n = values.shape[axis]
    if axis == 1:
        source = jnp.concatenate([values, values[:, :1]], 1) if wrap else jnp.pad(values, ((0, 0), (1, 1), (0, 0)))
        width = source.shape[1]
        flat = source.reshape(H * width, C)
        rows = jnp.arange(H, dtype=jnp.int32)[:, None] * width
    else:
        flat = values.reshape(H * W, C)
        cols = jnp.arange(W, dtype=jnp.int32)[None, :]

    def read(positions):
        i0 = jnp.floor(positions)
        f = (positions - i0)[..., None]
        i0 = i0.astype(jnp.int32)
        i1 = i0 + 1
        if wrap:
            inside0 = inside1 = 1.0
        else:
            inside0 = ((i0 >= 0) & (i0 < n))[..., None].astype(values.dtype)
            inside1 = ((i1 >= 0) & (i1 < n))[..., None].astype(values.dtype)
        if axis == 1:
            # Window start in the padded row: texel i0 sits at i0 (wrap) or i0 + 1 (zero pad);
            # texels far outside land on a pad or edge texel whose weight is zero.
            start = i0 % n if wrap else jnp.clip(i0, -1, n - 1) + 1
            window = jax.vmap(lambda at: jax.lax.dynamic_slice(flat, (at, jnp.int32(0)), (2, C)))(
                (rows + start).reshape(-1).astype(jnp.int32))
            window = window.reshape(H, W, 2, C)
            v0, v1 = window[..., 0, :], window[..., 1, :]
        else:
            if wrap:
                i0, i1 = i0 % n, i1 % n
            else:
                i0, i1 = jnp.clip(i0, 0, n - 1), jnp.clip(i1, 0, n - 1)
            v0, v1 = flat[i0 * W + cols], flat[i1 * W + cols]
        return (1 - f) * v0 * inside0 + f * v1 * inside1

    return read


def _shifted_lerp(values, axis: int, wrap: bool):
    """For one offset shared by every texel: ``read(x)`` is ``values`` (H, W, C) linearly
    interpolated at ``i + x`` along ``axis`` (x a traced scalar), its two reads slices at a
    traced start (``dynamic_slice``) instead of :func:`_gathered_lerp`'s per-texel gathers, with
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


@functools.partial(jax.custom_jvp, nondiff_argnums=(3, 4, 5))
def _blur_pass(texture, mask, spacing, axis: int, taps: int, wrap: bool):
    """One normalised 1D pass. ``spacing`` per texel (H, W) reads each tap by gathers; one
    scalar spacing for every texel (a uniform stretch) reads it by shifted slices.

    The taps are summed by a ``lax.scan`` rather than an unrolled sum: XLA:CPU drops
    ``optimization_barrier`` and fuses an unrolled sum into its consumers, so the normalisation
    recomputed every tap's reads once for the numerator and once for the weight, and the
    spacing's table search inside every gather. A loop's carry is materialised between taps:
    one pass on 512^2 x 4 went from 50 to 7 ms.

    Its derivative in the texture alone (:func:`_blur_pass_jvp`) is the pass without the
    mask's channel, divided by the primal's weight.
    """
    return _normalised_pass(texture, mask, spacing, axis, taps, wrap)[0]


def _taps(values, spacing, axis: int, taps: int, wrap: bool):
    r""":math:`\sum_k w_k\,v(i + x_k s_i)` along ``axis``: the pass's weighted reads of ``values`` (H, W, C)."""
    offsets, weights = kernel(taps)
    if jnp.ndim(spacing) == 0:
        shifted = _shifted_lerp(values, axis, wrap)

        def read(k):  # the tap k spacings away, for every texel at once
            return shifted(k * spacing)
    else:
        index = jnp.arange(values.shape[axis], dtype=spacing.dtype)
        base = index[:, None] if axis == 0 else index[None, :]
        gathered = _gathered_lerp(values, axis, wrap)

        def read(k):
            return gathered(base + k * spacing)

    def tap(total, offset_weight):
        offset, weight = offset_weight
        return total + weight * read(offset), None

    dtype = values.dtype
    total, _ = jax.lax.scan(tap, jnp.zeros_like(values), (jnp.asarray(offsets, dtype), jnp.asarray(weights, dtype)))
    return total


def _normalised_pass(texture, mask, spacing, axis: int, taps: int, wrap: bool):
    """The pass and its weight (the mask's own sum): texture and mask read together, as one
    (H, W, C + 1) array (a frame's forward pass: on 512^2 float32 4.3 ms against 7.1 ms apart)."""
    stacked = jnp.concatenate([texture * mask[..., None], mask[..., None]], axis=-1)
    total = _taps(stacked, spacing, axis, taps, wrap)
    numerator, weight = total[..., :-1], total[..., -1:]
    has = weight > 1e-12
    return jnp.where(has, numerator / jnp.where(has, weight, 1.0), 0.0) * mask[..., None], weight


def _blur_pass_jvp(axis, taps, wrap, primals, tangents):
    """In the texture alone (a fit's J v and, transposed, J^T w) the pass is linear with the
    primal's weight: the tangent's reads carry its C channels, not the mask's zero one, and no
    derivative of the normalisation (a 96^2 x 3 float64 step: J v 0.67 -> 0.38 ms, J^T w 0.85 ->
    0.43 ms). Where the mask or the spacing has a tangent too, JAX differentiates the pass itself."""
    texture, mask, spacing = primals
    d_texture, d_mask, d_spacing = tangents
    if not (type(d_mask) is SymbolicZero and type(d_spacing) is SymbolicZero):
        instantiated = tuple(jnp.zeros(t.shape, t.dtype) if type(t) is SymbolicZero else t for t in tangents)
        return jax.jvp(lambda *a: _normalised_pass(*a, axis, taps, wrap)[0], primals, instantiated)
    out, weight = _normalised_pass(texture, mask, spacing, axis, taps, wrap)
    has = weight > 1e-12
    numerator = _taps(d_texture * mask[..., None], spacing, axis, taps, wrap)
    return out, jnp.where(has, numerator / jnp.where(has, weight, 1.0), 0.0) * mask[..., None]


_blur_pass.defjvp(_blur_pass_jvp, symbolic_zeros=True)


def _per_axis(stretch, shape):
    """``stretch`` as (u, v) lengths [mm]: each one scalar (uniform along that axis's texels) or an
    (H, W) map. Accepts a (2,) pair, an (H, W, 2) or (H, W, 1) map, or such a (u, v) tuple."""
    if isinstance(stretch, tuple):
        return stretch
    if jnp.shape(stretch) == (2,):
        return stretch[0], stretch[1]
    stretch = jnp.broadcast_to(stretch, tuple(shape) + (2,))
    return stretch[..., 0], stretch[..., 1]


def _spacing(variance, length, size: int, taps: int):
    """Tap spacing [texels] for ``variance`` [mm^2] at texel ``length`` [mm] (scalar or map; 0 off the mask)."""
    if jnp.ndim(length) == 0:
        return spacing_for_variance(variance / length**2, taps=taps, max_spacing=size)
    safe = jnp.where(length > 0, length, 1.0)
    return jnp.where(length > 0, spacing_for_variance(variance / safe**2, taps=taps, max_spacing=size), 0.0)


def blur_step(texture, mask, stretch, variance, *, taps: int = 7, wrap_u: bool = False):
    """Blur ``texture`` (H, W, C) by a Gaussian of ``variance`` [mm^2] on the surface.

    Parameters
    ----------
    texture : array, shape (H, W, C)
    mask : array, shape (H, W)
        1 on valid texels, 0 elsewhere.
    stretch : array, shape (H, W, 2) or (2,), or a tuple (u, v)
        World length of one texel step along u and v [mm]: per texel, one pair for every texel
        (a plane), or per axis, each a scalar or an (H, W) map (a sphere's v is uniform, its u
        is not). An axis whose length is one scalar reads each tap as a shifted slice instead of
        the per-texel gathers a varying length needs, with the same result (one pass on
        512^2 x 4 on 2 CPU cores: 3 against 12 ms).
    variance : scalar [mm^2]
    """
    dtype = texture.dtype
    mask = jnp.asarray(mask, dtype)
    u, v = (jnp.asarray(length, dtype) for length in _per_axis(stretch, mask.shape))
    size = max(texture.shape[:2])
    out = _blur_pass(texture, mask, _spacing(variance, u, size, taps), 1, taps, wrap_u)
    return _blur_pass(out, mask, _spacing(variance, v, size, taps), 0, taps, False)


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
    """``stretch`` with every axis that has one length on all valid texels made a scalar: a NumPy
    (2,) pair where both do (a plane), a (u, v) tuple where one does (a sphere's v), else as it is.
    "One length" allows a relative spread of 1e-9 (rounding in the baked map). What invalid texels
    hold does not matter (they neither give nor receive light). Only concrete
    stretch maps are looked at (geometry is fixed, also during a fit)."""
    if not is_concrete((stretch, mask)):
        return stretch
    if isinstance(stretch, tuple) or np.shape(stretch) == (2,):
        return stretch
    values = np.asarray(stretch)
    valid = np.broadcast_to(np.asarray(mask) > 0, values.shape[:-1])
    values = np.broadcast_to(values, valid.shape + (2,))
    axes = []
    for axis in range(2):
        inside = values[..., axis][valid]
        # Equal to rounding: baked lengths along a sphere's v differ by 1e-15 between texels.
        uniform = inside.size and np.all(inside > 0) and np.ptp(inside) <= 1e-9 * inside[0]
        axes.append(np.asarray(inside[0], values.dtype) if uniform else values[..., axis])
    if all(a.ndim == 0 for a in axes):
        return np.stack(axes)
    if any(a.ndim == 0 for a in axes):
        return tuple(axes)
    return stretch


@functools.partial(jax.jit, static_argnames=("substeps", "taps", "wrap_u"))
def _chain(texture, mask, stretch, variances, first_variance_ratio, *, substeps, taps, wrap_u):
    # ``stretch``: a (2,) pair, an (H, W, 2) map or a (u, v) tuple (see blur_step); its form is
    # part of the compiled program's shape.
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
