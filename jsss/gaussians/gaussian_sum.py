r"""Sums of 2D Gaussians: the representation, its algebra and the d'Eon error metric.

A normalised radial 2D Gaussian of variance :math:`v` [mm^2] is

.. math:: G(v, r) = \frac{1}{2\pi v} e^{-r^2 / 2v}, \qquad 2\pi\int_0^\infty G(v, r)\,r\,dr = 1,

and 2D convolution adds variances: :math:`G(v_1) * G(v_2) = G(v_1 + v_2)` (d'Eon et al. 2007
eq. 11). A :class:`GaussianSum` is :math:`\sum_i w_i G(v_i, r)` with a channel axis on the
weights; its total diffuse response is :math:`\sum_i w_i`. A variance of exactly 0 is a
:math:`\delta` at ``r = 0`` (light passing straight through a layer); it has a total but no
value at ``r > 0``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..numerics import append_axes, as_float_array, is_concrete

__all__ = [
    "GaussianSum",
    "add",
    "convolve",
    "evaluate",
    "gaussian",
    "reduce_to",
    "relative_rms_error",
    "scale",
    "second_moment",
    "total",
]


def gaussian(v, r):
    r""":math:`G(v, r) = e^{-r^2/2v} / (2\pi v)` [1/mm^2]; 0 where ``v = 0`` (a delta)."""
    v = as_float_array(v)
    positive = v > 0
    safe_v = jnp.where(positive, v, 1.0)
    return jnp.where(positive, jnp.exp(-jnp.square(r) / (2 * safe_v)) / (2 * jnp.pi * safe_v), 0.0)


class GaussianSum(eqx.Module):
    r""":math:`\sum_i w_i G(v_i, r)`: weights ``(n,) + C`` and variances ``(n,)`` in mm^2.

    Parameters
    ----------
    weights : array_like, shape ``(n,)`` or ``(n,) + C``
        Dimensionless (each Gaussian's total response); may be negative.
    variances : array_like, shape ``(n,)`` [mm^2]
        >= 0 (0 is a delta). Checked when concrete.
    """

    weights: jax.Array
    variances: jax.Array

    def __init__(self, weights, variances):
        weights, variances = as_float_array(weights), as_float_array(variances)
        if variances.ndim != 1 or weights.ndim < 1 or weights.shape[0] != variances.shape[0]:
            raise ValueError(
                "GaussianSum needs variances of shape (n,) and weights of shape (n,) or (n, C...); "
                f"got weights {weights.shape} and variances {variances.shape}."
            )
        if is_concrete(variances) and np.any(~np.isfinite(np.asarray(variances)) | (np.asarray(variances) < 0)):
            raise ValueError(f"GaussianSum(variances=...) must be finite and >= 0 [mm^2]; got {np.asarray(variances)!r}.")
        self.weights = weights
        self.variances = variances

    @property
    def n_terms(self) -> int:
        return int(self.variances.shape[0])

    @property
    def channel_shape(self) -> tuple[int, ...]:
        return tuple(self.weights.shape[1:])


def evaluate(gs: GaussianSum, r):
    """The sum at radii ``r`` (any shape ``S``): shape ``S + C`` [1/mm^2]."""
    r = as_float_array(r)
    channels = len(gs.channel_shape)
    # (S..., n) Gaussians, then contract n against weights (n, C...).
    g = gaussian(gs.variances, r[..., None])
    return jnp.tensordot(g, gs.weights, axes=([g.ndim - 1], [0])) if channels else g @ gs.weights


def total(gs: GaussianSum):
    r"""Total diffuse response :math:`\sum_i w_i` (shape ``C``)."""
    return jnp.sum(gs.weights, axis=0)


def second_moment(gs: GaussianSum):
    r""":math:`2\pi\int r^2\,\sum_i w_i G(v_i, r)\,r\,dr = \sum_i 2 v_i w_i` [mm^2] (shape ``C``)."""
    return jnp.tensordot(2 * gs.variances, gs.weights, axes=1)


def scale(gs: GaussianSum, factor) -> GaussianSum:
    """The sum with every weight multiplied by ``factor`` (broadcast over channels)."""
    return GaussianSum(gs.weights * factor, gs.variances)


def add(a: GaussianSum, b: GaussianSum) -> GaussianSum:
    """``a + b``: the terms of both (weights broadcast to a common channel shape)."""
    shape = jnp.broadcast_shapes(a.channel_shape, b.channel_shape)
    wa = jnp.broadcast_to(a.weights, (a.n_terms,) + shape)
    wb = jnp.broadcast_to(b.weights, (b.n_terms,) + shape)
    return GaussianSum(jnp.concatenate([wa, wb]), jnp.concatenate([a.variances, b.variances]))


def convolve(a: GaussianSum, b: GaussianSum) -> GaussianSum:
    r"""2D convolution ``a * b``: all pairs, variances add and weights multiply (eq. 12)."""
    shape = jnp.broadcast_shapes(a.channel_shape, b.channel_shape)
    wa = jnp.broadcast_to(a.weights, (a.n_terms,) + shape)[:, None]
    wb = jnp.broadcast_to(b.weights, (b.n_terms,) + shape)[None, :]
    variances = (a.variances[:, None] + b.variances[None, :]).reshape(-1)
    return GaussianSum((wa * wb).reshape((-1,) + shape), variances)


def reduce_to(gs: GaussianSum, variances) -> GaussianSum:
    r"""Approximate ``gs`` on a sparser, sorted set of ``variances`` (d'Eon sec. 5).

    Each term of variance :math:`v` between neighbours :math:`u_a \le v \le u_b` of the
    sparse set is split as :math:`\lambda w G(u_a) + (1-\lambda) w G(u_b)` with
    :math:`\lambda = (u_b - v)/(u_b - u_a)`, which keeps both its total and its second
    moment :math:`2 v w`. Terms outside the range go to the nearest end (total kept).

    Parameters
    ----------
    gs : GaussianSum
    variances : array_like, shape ``(m,)``, strictly increasing [mm^2]

    Returns
    -------
    GaussianSum on ``variances``.
    """
    target = as_float_array(variances)
    if is_concrete(target) and (target.ndim != 1 or np.any(np.diff(np.asarray(target)) <= 0)):
        raise ValueError(f"reduce_to(variances=...) must be 1-D and strictly increasing; got {np.asarray(target)!r}.")
    m = target.shape[0]
    v = jnp.clip(gs.variances, target[0], target[-1])
    upper = jnp.clip(jnp.searchsorted(target, v, side="left"), 1, m - 1)
    lower = upper - 1
    ua, ub = target[lower], target[upper]
    lam = (ub - v) / (ub - ua)
    channel_axes = len(gs.channel_shape)
    lam = append_axes(lam, channel_axes)
    weights = jnp.zeros((m,) + gs.weights.shape[1:], dtype=gs.weights.dtype)
    weights = weights.at[lower].add(lam * gs.weights).at[upper].add((1 - lam) * gs.weights)
    return GaussianSum(weights, target)


def relative_rms_error(gs: GaussianSum, r, profile):
    r"""Relative RMS power error of d'Eon eq. 10, as a fraction (0.0152 = 1.52 %).

    .. math:: \sqrt{\int r (R - G_{sum})^2 dr} \Big/ \sqrt{\int r R^2 dr}

    evaluated by the trapezoid rule on the given (possibly log-spaced) radii.

    Parameters
    ----------
    gs : GaussianSum
    r : array_like, shape ``(N,)``, increasing [mm]
    profile : array_like, shape ``(N,) + C`` [1/mm^2]
    """
    r = as_float_array(r)
    profile = as_float_array(profile)
    residual = profile - evaluate(gs, r)
    w = append_axes(r, profile.ndim - 1)
    num = jnp.trapezoid(w * residual**2, r, axis=0)
    den = jnp.trapezoid(w * profile**2, r, axis=0)
    return jnp.sqrt(num / den)
