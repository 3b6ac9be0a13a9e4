r"""The dipole diffusion profile of a semi-infinite medium (Jensen et al. 2001, sec. 2.1-2.4).

A normally incident beam becomes a real point source at depth :math:`z_r = 1/\sigma_t'`
and a negative image source at height :math:`z_v = z_r + 4AD` above the surface.
The radiant exitance per unit incident flux at distance :math:`r` from the entry point is
(Jensen eq. 4)

.. math::

    R_d(r) = \frac{\alpha'}{4\pi}\left[
        z_r (1 + \sigma_{tr} d_r)\frac{e^{-\sigma_{tr} d_r}}{d_r^3} +
        z_v (1 + \sigma_{tr} d_v)\frac{e^{-\sigma_{tr} d_v}}{d_v^3}\right],
    \qquad d_{r,v} = \sqrt{r^2 + z_{r,v}^2},

and its integral over the plane has the closed form (sec. 2.4)

.. math::

    R_d = 2\pi\int_0^\infty R_d(r)\,r\,dr
        = \frac{\alpha'}{2}\left(e^{-\sigma_{tr} z_r} + e^{-\sigma_{tr} z_v}\right)
        = \frac{\alpha'}{2}\left(1 + e^{-\frac43 A\sqrt{3(1-\alpha')}}\right) e^{-\sqrt{3(1-\alpha')}}.

All lengths are in mm, coefficients in 1/mm, :math:`R_d(r)` in 1/mm^2.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ..fresnel import exit_lobe, internal_reflection_parameter
from ..medium import Medium
from ..numerics import (
    append_axes,
    as_float_array,
    is_concrete,
    safe_sqrt,
    warn_if_low_precision,
)

__all__ = [
    "medium_from_reflectance",
    "pole_profile",
    "profile",
    "radiance",
    "reduced_albedo_from_reflectance",
    "source_depths",
    "spectrum",
    "total_reflectance",
]


@jax.custom_jvp
def _decay(kappa, d):
    r""":math:`(1 + \sigma d)\,e^{-\sigma d}` with :math:`\sigma = \sqrt{\kappa}`.

    Written in :math:`\kappa = \sigma_{tr}^2 = 3\sigma_a\sigma_t'` because the function is
    smooth in :math:`\kappa` even at 0, where it is not smooth in :math:`\sigma_a` through
    :math:`\sqrt{\cdot}`: the derivatives below are finite everywhere.
    """
    sigma_d = jnp.sqrt(jnp.maximum(kappa, 0)) * d
    return (1 + sigma_d) * jnp.exp(-sigma_d)


@_decay.defjvp
def _decay_jvp(primals, tangents):
    kappa, d = primals
    dkappa, dd = tangents
    sigma = jnp.sqrt(jnp.maximum(kappa, 0))
    e = jnp.exp(-sigma * d)
    value = (1 + sigma * d) * e
    # d/dkappa = -d^2 e / 2 ; d/dd = -kappa d e
    return value, -0.5 * d**2 * e * dkappa - kappa * d * e * dd


def pole_profile(z, kappa, r):
    r"""One pole's term :math:`z (1 + \sigma d) e^{-\sigma d} / d^3`, :math:`d = \sqrt{r^2+z^2}`.

    Parameters
    ----------
    z : array_like, mm
        Signed source height (the sign carries through; :math:`d` uses :math:`|z|`).
    kappa : array_like, 1/mm^2
        :math:`\sigma_{tr}^2 = 3 \sigma_a \sigma_t'`, >= 0.
    r : array_like, mm
        Distance along the surface, broadcast against ``z``.

    Returns
    -------
    Array, 1/mm^2 (before the factor :math:`\alpha'/4\pi`). Finite for ``r = 0`` when
    ``z != 0``; ``d`` is formed with ``hypot`` so very large ``r`` does not overflow.
    """
    d = jnp.hypot(r, z)
    return (z / d) * _decay(kappa, d) / d**2


def source_depths(medium: Medium):
    r"""Depth of the real source :math:`z_r = 1/\sigma_t'` and height of the virtual one
    :math:`z_v = z_r + 4AD` [mm], each of ``medium.shape``."""
    z_r = medium.mean_free_path
    z_v = z_r + 4.0 * medium.internal_reflection * medium.diffusion_coefficient
    return z_r, z_v


@jax.jit  # one program: op by op, 0.8 s per call before a render's first pixel
def profile(medium: Medium, r):
    r"""Dipole diffuse reflectance profile :math:`R_d(r)` (Jensen 2001 eq. 4) in 1/mm^2.

    Parameters
    ----------
    medium : Medium
        Of shape ``C`` (e.g. ``(3,)`` for RGB, ``()`` for one channel).
    r : array_like, mm
        Distances from the point of incidence, any shape ``S``; ``r = 0`` is fine.

    Returns
    -------
    R : Array of shape ``S + C``, 1/mm^2, >= 0.

    Notes
    -----
    Gradients are finite everywhere, including with respect to ``sigma_a`` at
    ``sigma_a = 0``: the profile is smooth in :math:`\sigma_{tr}^2` there (see ``_decay``).
    """
    r = append_axes(as_float_array(r), len(medium.shape))
    z_r, z_v = source_depths(medium)
    kappa = 3.0 * medium.sigma_a * medium.sigma_t_prime
    poles = pole_profile(z_r, kappa, r) + pole_profile(z_v, kappa, r)
    return medium.reduced_albedo / (4 * jnp.pi) * poles


def radiance(medium: Medium, r, cos_exit):
    r"""Radiance leaving toward ``cos_exit`` [1/(mm^2 sr)] per unit entering flux, by the
    diffusion exit law: :func:`profile` times :func:`jsss.fresnel.exit_lobe`.

    What a camera sees of the dipole (the counterpart of :func:`jsss.transport.radiance`).
    ``r`` and ``cos_exit`` broadcast together (shape ``S``); the result is ``S + C``.
    Diffusion puts the angular law of the far field everywhere; near the source the real
    radiance toward a camera looking down is lower (a quarter transport length out, by about
    0.6 at eta 1.3-1.5).
    """
    r, cos_exit = jnp.broadcast_arrays(as_float_array(r), as_float_array(cos_exit))
    lobe = exit_lobe(append_axes(cos_exit, len(medium.shape)), medium.eta)
    return profile(medium, r) * lobe


@jax.jit
def total_reflectance(medium: Medium):
    r"""Total diffuse reflectance :math:`R_d = 2\pi\int_0^\infty R_d(r) r\,dr` (closed form).

    Parameters
    ----------
    medium : Medium

    Returns
    -------
    Rd : Array of ``medium.shape``, in [0, 1]; exactly 1 when ``sigma_a = 0``.

    Notes
    -----
    :math:`\partial R_d / \partial\sigma_a` is :math:`-\infty` at ``sigma_a = 0`` (the
    total falls like :math:`\sqrt{\sigma_a}`). There the gradient is returned as a large
    finite negative number (of order -1e154 in float64, -1e19 in float32), never NaN.
    """
    z_r, z_v = source_depths(medium)
    sigma_tr = medium.sigma_tr
    return 0.5 * medium.reduced_albedo * (jnp.exp(-sigma_tr * z_r) + jnp.exp(-sigma_tr * z_v))


def spectrum(medium: Medium, k):
    r"""Hankel transform of the profile, :math:`2\pi\int_0^\infty R_d(r) J_0(kr)\,r\,dr`.

    Each pole transforms in closed form, :math:`\tfrac{1}{2}e^{-z\beta}` with
    :math:`\beta = \sqrt{k^2 + \sigma_{tr}^2}`, so

    .. math:: \hat R_d(k) = \frac{\alpha'}{2}\left(e^{-z_r\beta} + e^{-z_v\beta}\right),

    and ``spectrum(medium, 0) == total_reflectance(medium)``.

    Parameters
    ----------
    medium : Medium
        Of shape ``C``.
    k : array_like, rad/mm
        Spatial frequencies, shape ``S``.

    Returns
    -------
    Array of shape ``S + C``, dimensionless.
    """
    k = append_axes(as_float_array(k), len(medium.shape))
    z_r, z_v = source_depths(medium)
    beta = safe_sqrt(k**2 + 3.0 * medium.sigma_a * medium.sigma_t_prime)
    return 0.5 * medium.reduced_albedo * (jnp.exp(-beta * z_r) + jnp.exp(-beta * z_v))


def _total_from_root(s, A):
    r"""Total reflectance as a function of :math:`s = \sqrt{3(1-\alpha')}` and A.

    Strictly decreasing on :math:`[0, \sqrt3]` from 1 to 0 (every factor is).
    """
    return 0.5 * (1 - s**2 / 3) * (1 + jnp.exp(-4.0 / 3.0 * A * s)) * jnp.exp(-s)


def reduced_albedo_from_reflectance(total_rd, eta, *, bisection_steps: int = 64):
    r"""Invert :func:`total_reflectance` for the reduced albedo :math:`\alpha'`.

    The total reflectance depends on :math:`\alpha'` and :math:`\eta` only. It is solved
    for :math:`s = \sqrt{3(1 - \alpha')}` by bisection on :math:`[0, \sqrt{3}]` (where it
    is strictly decreasing), then one Newton step from the stopped-gradient root gives
    the implicit-function derivative, so ``grad`` works.

    Parameters
    ----------
    total_rd : array_like
        Total diffuse reflectance in [0, 1] (clipped there under tracing).
    eta : array_like
        Relative index of refraction, > 0; broadcast with ``total_rd``.
    bisection_steps : int, keyword-only
        64 reaches float64 round-off.

    Returns
    -------
    alpha_prime : Array in [0, 1]
    one_minus_alpha_prime : Array, :math:`1-\alpha'` computed without cancellation
    """
    rd = jnp.clip(as_float_array(total_rd), 0.0, 1.0)
    A = internal_reflection_parameter(eta)
    rd, A = jnp.broadcast_arrays(rd, A)
    rd_fixed, A_fixed = lax.stop_gradient(rd), lax.stop_gradient(A)

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        above = _total_from_root(mid, A_fixed) > rd_fixed  # root lies further right
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    lo = jnp.zeros_like(rd)
    hi = jnp.full_like(rd, np.sqrt(3.0))
    lo, hi = lax.fori_loop(0, bisection_steps, bisect, (lo, hi))
    s_root = lax.stop_gradient(0.5 * (lo + hi))

    residual = _total_from_root(s_root, A) - rd
    _, slope = jax.jvp(lambda s: _total_from_root(s, A_fixed), (s_root,), (jnp.ones_like(s_root),))
    s = s_root - residual / slope
    one_minus_alpha = s**2 / 3
    return 1 - one_minus_alpha, one_minus_alpha


def medium_from_reflectance(total_rd, mean_free_path, eta=1.3) -> Medium:
    r"""The medium with a given total diffuse reflectance and mean free path.

    The artist's parameterisation: total diffuse reflectance ("colour") and the
    reduced mean free path :math:`\ell = 1/\sigma_t'` ("translucency"), per channel.
    :math:`\alpha'` comes from :func:`reduced_albedo_from_reflectance`; then
    :math:`\sigma_s' = \alpha'/\ell` and :math:`\sigma_a = (1-\alpha')/\ell`.
    ``total_reflectance(medium_from_reflectance(R, l, eta))`` returns ``R`` to 1e-8
    in float64 (float32 warns: it reaches about 1e-6).

    Parameters
    ----------
    total_rd : array_like
        Total diffuse reflectance in [0, 1].
    mean_free_path : array_like, mm
        :math:`1/\sigma_t'`, > 0.
    eta : array_like, default 1.3
        Relative index, > 0.

    Returns
    -------
    Medium

    Raises
    ------
    ValueError
        For concrete inputs out of range, naming the parameter.
    """
    if is_concrete((total_rd, mean_free_path, eta)):
        rd = np.asarray(total_rd, dtype=float)
        if not np.all(np.isfinite(rd)) or np.any((rd < 0) | (rd > 1)):
            raise ValueError(
                f"medium_from_reflectance(total_rd=...) must lie in [0, 1]; got {total_rd!r}."
            )
        mfp = np.asarray(mean_free_path, dtype=float)
        if not np.all(np.isfinite(mfp)) or np.any(mfp <= 0):
            raise ValueError(
                "medium_from_reflectance(mean_free_path=...) must be finite and > 0 [mm]; "
                f"got {mean_free_path!r}."
            )
        if np.any(np.asarray(eta, dtype=float) <= 0):
            raise ValueError(f"medium_from_reflectance(eta=...) must be > 0; got {eta!r}.")
    total_rd = as_float_array(total_rd)
    warn_if_low_precision(
        total_rd, what="medium_from_reflectance", needs="its 1e-8 round-trip accuracy"
    )
    alpha, one_minus_alpha = reduced_albedo_from_reflectance(total_rd, eta)
    sigma_t = 1.0 / as_float_array(mean_free_path)
    return Medium(one_minus_alpha * sigma_t, alpha * sigma_t, eta)
