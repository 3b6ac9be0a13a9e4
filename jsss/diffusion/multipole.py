r"""The multipole of a finite slab (Donner & Jensen 2005; d'Eon et al. 2007 sec. 3).

A slab of thickness :math:`d` with extrapolated boundaries :math:`z_{b,top} = 2 A_{top} D` above
and :math:`z_{b,bottom} = 2 A_{bottom} D` below is modelled by a real source at depth
:math:`z_0` and an infinite train of image pairs with period
:math:`P = 2 (d + z_{b,top} + z_{b,bottom})`:

.. math::

    z_{r,i} = i P + z_0, \qquad z_{v,i} = i P - z_0 - 2 z_{b,top}, \qquad i \in \mathbb{Z},

    R(r) = \frac{w\alpha'}{4\pi}\sum_i \left[\phi(z_{r,i}, r) - \phi(z_{v,i}, r)\right],\qquad
    T(r) = \frac{w\alpha'}{4\pi}\sum_i \left[\phi(d - z_{r,i}, r) - \phi(d - z_{v,i}, r)\right],

with the pole term :math:`\phi(z, r) = z (1 + \sigma_{tr} d_z) e^{-\sigma_{tr} d_z} / d_z^3`,
:math:`d_z = \sqrt{r^2 + z^2}` (:func:`jsss.diffusion.dipole.pole_profile`).

**Closed forms.** Each pole has the exact Hankel transform
:math:`2\pi\int_0^\infty \phi(z, r) J_0(kr)\,r\,dr / 4\pi = \mathrm{sign}(z)\,e^{-|z|\beta}/2` with
:math:`\beta = \sqrt{k^2 + \sigma_{tr}^2}`, and the sum over the whole image train is a pair of
geometric series:

.. math::

    \sum_i \mathrm{sign}(iP + c)\,e^{-\beta |iP + c|}
      = e^{-\beta c'}\,\frac{1 - e^{-\beta (P - 2c')}}{1 - e^{-\beta P}},\qquad c' = c \bmod P,

which tends to :math:`1 - 2c'/P` as :math:`\beta \to 0`. So :func:`slab_totals` (k = 0) and
:func:`slab_spectra` (any k) are exact sums of *all* poles, with no truncation and no
quadrature; with :math:`\sigma_a = 0` they give :math:`R + T = w` exactly. Only the profiles in
``r`` truncate the train, at ``n_dipoles`` pairs on each side.

**The source.** Donner & Jensen put the real source one reduced mean free path
:math:`\ell = 1/\sigma_t'` deep. For slabs thinner than :math:`\ell` that source lies below the
slab and the totals go wrong (with :math:`\sigma_a = 0`, :math:`T = (2\ell - 2d - 2z_{b,bottom})/P`,
which is negative). We instead place it at the mean depth of the first collision *within* the
slab and weight it by the probability that a collision happens there:

.. math:: z_0 = \ell - \frac{d}{e^{d/\ell} - 1}, \qquad w = 1 - e^{-d/\ell},

which equals :math:`(\ell, 1)` up to :math:`e^{-d/\ell}` for thick slabs (so the dipole is the
limit) and tends to :math:`(d/2, d/\ell)` for thin ones. The remaining fraction
:math:`e^{-d/\ell}` crosses the slab unscattered (:func:`unscattered_transmittance`).
``source="mean-free-path"`` restores Donner & Jensen's :math:`(z_0, w) = (\ell, 1)`.
"""

from __future__ import annotations

from typing import Literal

import jax.numpy as jnp
import numpy as np
from jax import lax

from .dipole import pole_profile
from ..fresnel import internal_reflection_parameter
from ..medium import Medium
from ..numerics import append_axes, as_float_array, is_concrete, safe_sqrt

__all__ = [
    "SlabGeometry",
    "choose_n_dipoles",
    "slab_geometry",
    "slab_profiles",
    "slab_spectra",
    "slab_totals",
    "unscattered_transmittance",
]

Source = Literal["first-collision", "mean-free-path"]
_SOURCES = ("first-collision", "mean-free-path")
#: Pairs per side used when ``n_dipoles=None`` but the inputs are traced (inside jit/grad).
TRACED_N_DIPOLES = 64


class SlabGeometry:
    """Source depth, weight, extrapolation distances and image period of a slab (arrays)."""

    __slots__ = ("thickness", "z0", "weight", "zb_top", "zb_bottom", "period")

    def __init__(self, thickness, z0, weight, zb_top, zb_bottom, period):
        self.thickness = thickness
        self.z0 = z0
        self.weight = weight
        self.zb_top = zb_top
        self.zb_bottom = zb_bottom
        self.period = period


def _check_slab(thickness, eta_top, eta_bottom, source):
    if source not in _SOURCES:
        raise ValueError(f"source={source!r} is not one of {_SOURCES}.")
    if is_concrete((thickness, eta_top, eta_bottom)):
        d = np.asarray(thickness, dtype=float)
        if not np.all(np.isfinite(d)) or np.any(d < 0):
            raise ValueError(f"thickness must be finite and >= 0 [mm]; got {thickness!r}.")
        for name, value in (("eta_top", eta_top), ("eta_bottom", eta_bottom)):
            if value is not None and np.any(np.asarray(value, dtype=float) <= 0):
                raise ValueError(f"{name} must be > 0 (a relative index); got {value!r}.")


def slab_geometry(medium: Medium, thickness, *, eta_top=None, eta_bottom=None,
                  source: Source = "first-collision") -> SlabGeometry:
    """Geometry of the image train; ``eta_top``/``eta_bottom`` default to ``medium.eta``.

    Each is the slab's index relative to the medium on that side (1.0 for a matched
    boundary, ``medium.eta`` against air).
    """
    _check_slab(thickness, eta_top, eta_bottom, source)
    d = as_float_array(thickness)
    eta_top = medium.eta if eta_top is None else as_float_array(eta_top)
    eta_bottom = medium.eta if eta_bottom is None else as_float_array(eta_bottom)
    ell = medium.mean_free_path
    D = medium.diffusion_coefficient
    zb_top = 2 * internal_reflection_parameter(eta_top) * D
    zb_bottom = 2 * internal_reflection_parameter(eta_bottom) * D
    if source == "mean-free-path":
        z0 = ell * jnp.ones_like(d)
        weight = jnp.ones_like(z0)
    else:
        x = d / ell
        small = x < 1e-6
        safe_x = jnp.where(small, 1.0, x)
        # z0 = ell (1 - x / expm1(x)), written with e^{-x} so that neither the value nor
        # its derivative overflows for thick slabs; -> d/2 as x -> 0 (series branch).
        fraction = safe_x * jnp.exp(-safe_x) / -jnp.expm1(-safe_x)
        z0 = jnp.where(small, 0.5 * d, ell * (1 - fraction))
        weight = -jnp.expm1(-x)
    period = 2 * (d + zb_top + zb_bottom)
    return SlabGeometry(d, z0, weight, zb_top, zb_bottom, period)


def unscattered_transmittance(medium: Medium, thickness):
    r"""Fraction :math:`e^{-d/\ell}` that crosses the slab before its first (reduced) collision."""
    return jnp.exp(-as_float_array(thickness) * medium.sigma_t_prime)


def _image_train_sum(c, period, beta):
    r""":math:`\sum_i \mathrm{sign}(iP + c) e^{-\beta|iP + c|}` in closed form (module docstring).

    Written as :math:`[e^{-\beta c'} - e^{-\beta(P - c')}] / (1 - e^{-\beta P})` with every
    exponent <= 0 (no overflow at large k) and ``expm1`` for the small-:math:`\beta`
    cancellation; the :math:`\beta = 0` limit :math:`1 - 2c'/P` is taken explicitly.
    """
    c_mod = jnp.mod(c, period)
    positive = beta > 0
    b = jnp.where(positive, beta, 1.0)
    value = (jnp.expm1(-b * c_mod) - jnp.expm1(-b * (period - c_mod))) / -jnp.expm1(-b * period)
    return jnp.where(positive, value, 1 - 2 * c_mod / period)


def slab_spectra(medium: Medium, thickness, k, *, eta_top=None, eta_bottom=None,
                 source: Source = "first-collision"):
    r"""Exact Hankel transforms :math:`\hat R(k), \hat T(k)` of the slab's profiles.

    :math:`\hat P(k) = 2\pi\int_0^\infty P(r) J_0(kr)\,r\,dr`, summed over all image poles in
    closed form (module docstring). ``k = 0`` gives the totals.

    Parameters
    ----------
    medium : Medium
        Of shape ``C``.
    thickness : array_like, mm
        Broadcast against ``C``.
    k : array_like, rad/mm
        Spatial frequencies, shape ``S``.

    Returns
    -------
    R_hat, T_hat : Arrays of shape ``S + C``, dimensionless.
    """
    geo = slab_geometry(medium, thickness, eta_top=eta_top, eta_bottom=eta_bottom, source=source)
    k = append_axes(as_float_array(k), len(jnp.broadcast_shapes(medium.shape, jnp.shape(geo.thickness))))
    beta = safe_sqrt(k**2 + 3 * medium.sigma_a * medium.sigma_t_prime)
    scale = 0.5 * geo.weight * medium.reduced_albedo
    d, z0, zt, P = geo.thickness, geo.z0, geo.zb_top, geo.period
    R = scale * (_image_train_sum(z0, P, beta) - _image_train_sum(-z0 - 2 * zt, P, beta))
    T = scale * (_image_train_sum(d - z0, P, beta) - _image_train_sum(d + z0 + 2 * zt, P, beta))
    return R, T


def slab_totals(medium: Medium, thickness, *, eta_top=None, eta_bottom=None,
                source: Source = "first-collision"):
    r"""Total diffuse reflectance and transmittance of the slab (all poles, closed form).

    Returns
    -------
    R, T : Arrays of the broadcast shape of ``medium`` and ``thickness``, with
        ``R + T <= 1 - unscattered_transmittance`` (equality when ``sigma_a = 0``).
    """
    return slab_spectra(medium, thickness, 0.0, eta_top=eta_top, eta_bottom=eta_bottom,
                        source=source)


def choose_n_dipoles(medium: Medium, thickness, *, tol: float = 1e-6, eta_top=None,
                     eta_bottom=None, max_pairs: int = 2000) -> int:
    r"""Image pairs per side so that the omitted ones change the profile by under ``tol``.

    A pair at distance :math:`iP` contributes :math:`\sim e^{-\sigma_{tr} i P}` with absorption
    and :math:`\sim (z_0 / iP)^3` without; the tail beyond ``n`` is below ``tol`` of the
    leading pole when :math:`n \ge \ln(1/tol) / (\sigma_{tr}P)` or :math:`n \ge (z_0/P)
    \,tol^{-1/2}`, whichever is smaller. Needs concrete inputs.
    """
    geo = slab_geometry(medium, thickness, eta_top=eta_top, eta_bottom=eta_bottom)
    period = np.asarray(geo.period, dtype=float)
    z0 = np.asarray(geo.z0, dtype=float)
    sigma_tr = np.asarray(medium.sigma_tr, dtype=float)
    with np.errstate(divide="ignore"):
        by_absorption = np.where(sigma_tr > 0, np.log(1 / tol) / (sigma_tr * period), np.inf)
    by_distance = z0 / period / np.sqrt(tol) + 1
    n = np.ceil(np.minimum(by_absorption, by_distance))
    return int(np.clip(np.max(n), 1, max_pairs))


def slab_profiles(medium: Medium, thickness, r, *, eta_top=None, eta_bottom=None,
                  n_dipoles: int | None = None, tol: float = 1e-6,
                  source: Source = "first-collision"):
    r"""Reflectance and transmittance profiles :math:`R(r), T(r)` of a slab [1/mm^2].

    Parameters
    ----------
    medium : Medium
        Of shape ``C``.
    thickness : array_like, mm
        >= 0, broadcast against ``C``.
    r : array_like, mm
        Distances from the point of incidence, shape ``S``.
    eta_top, eta_bottom : array_like, optional, keyword-only
        Index of the slab relative to the medium above / below (default ``medium.eta``,
        i.e. air on both sides).
    n_dipoles : int, optional, keyword-only
        Image pairs on each side of the real one (``2 n + 1`` pairs in all). ``None``
        picks it with :func:`choose_n_dipoles` from ``tol`` for concrete inputs, and uses
        :data:`TRACED_N_DIPOLES` inside jit/grad (pass it explicitly there).
    tol : float, keyword-only
        Relative size of the omitted image pairs when ``n_dipoles`` is ``None``.
    source : {"first-collision", "mean-free-path"}, keyword-only
        Where the real source sits (module docstring).

    Returns
    -------
    R, T : Arrays of shape ``S + C`` (``C`` broadcast with the thickness's shape).
    """
    geo = slab_geometry(medium, thickness, eta_top=eta_top, eta_bottom=eta_bottom, source=source)
    if n_dipoles is None:
        if is_concrete((medium, thickness)):
            n_dipoles = choose_n_dipoles(medium, thickness, tol=tol, eta_top=eta_top,
                                         eta_bottom=eta_bottom)
        else:
            n_dipoles = TRACED_N_DIPOLES
    if int(n_dipoles) < 0:
        raise ValueError(f"n_dipoles must be >= 0; got {n_dipoles!r}.")
    channel_ndim = len(jnp.broadcast_shapes(medium.shape, jnp.shape(geo.thickness)))
    r = append_axes(as_float_array(r), channel_ndim)
    kappa = 3 * medium.sigma_a * medium.sigma_t_prime
    d, z0, zt, P = geo.thickness, geo.z0, geo.zb_top, geo.period

    def add_pair(i, carry):
        R, T = carry
        z_real = i * P + z0
        z_virtual = i * P - z0 - 2 * zt
        R = R + pole_profile(z_real, kappa, r) - pole_profile(z_virtual, kappa, r)
        T = T + pole_profile(d - z_real, kappa, r) - pole_profile(d - z_virtual, kappa, r)
        return R, T

    shape = jnp.broadcast_shapes(r.shape, jnp.shape(P))
    zeros = jnp.zeros(shape, dtype=jnp.result_type(r, P))
    n = int(n_dipoles)
    R, T = lax.fori_loop(-n, n + 1, lambda i, c: add_pair(i.astype(zeros.dtype), c), (zeros, zeros))
    scale = geo.weight * medium.reduced_albedo / (4 * jnp.pi)
    return scale * R, scale * T
