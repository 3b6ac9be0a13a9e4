r"""Exact importance sampling of the dipole (Mertens et al. 2003 sec. 4) and MIS.

Radii are drawn with density :math:`p(r) = 2\pi r R_d(r) / \rho`, :math:`\rho` the total
diffuse reflectance. Each pole integrates to :math:`\tfrac12 e^{-\sigma_{tr} z}` (times
:math:`\alpha'`), so a pole is chosen with probability proportional to
:math:`e^{-\sigma_{tr} z}`; its radial CDF inverts through :math:`u = \sqrt{1 + (r/z)^2}`:

.. math:: \sigma_{tr} z (u - 1) + \ln u + \ln(1 - \xi) = 0, \qquad r = z\sqrt{u^2 - 1}.

We solve it for :math:`t = \ln u \ge 0`, where :math:`g(t) = \sigma_{tr} z (e^t - 1) + t +
\ln(1-\xi)` is convex and increasing with :math:`g(0) \le 0`: Newton from :math:`t = 0` jumps
past the root once and then converges monotonically, for any :math:`\xi`. With
:math:`\ln(1-\xi)` from ``log1p`` and :math:`u^2 - 1 = \mathrm{expm1}(2t)`, :math:`\xi \to 0`
gives :math:`r \to 0` without cancellation; :math:`\xi` is clipped below 1 so the largest radius
is finite.

Shapes: a medium of shape ``C`` and uniform numbers of shape ``S`` give ``S + C``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .dipole import profile, source_depths, total_reflectance
from ..medium import Medium
from ..numerics import append_axes, as_float_array

__all__ = ["dipole_cdf", "dipole_pdf", "mis_integrate", "sample_dipole_radius"]


def _solve_log_u(sigma_z, log_one_minus_xi, iterations: int = 40):
    def step(_, t):
        e = jnp.exp(t)
        g = sigma_z * (e - 1) + t + log_one_minus_xi
        return t - g / (sigma_z * e + 1)

    return jax.lax.fori_loop(0, iterations, step, jnp.zeros_like(sigma_z + log_one_minus_xi))


def _pole_choice(medium):
    z_r, z_v = source_depths(medium)
    sigma = medium.sigma_tr
    real, virtual = jnp.exp(-sigma * z_r), jnp.exp(-sigma * z_v)
    return z_r, z_v, sigma, real / (real + virtual)


def sample_dipole_radius(medium: Medium, xi_pole, xi_radius):
    r"""Radii [mm] distributed as :math:`2\pi r R_d(r)/\rho` from two uniform numbers each.

    Parameters
    ----------
    medium : Medium
    xi_pole, xi_radius : array_like in [0, 1), shape ``S``
        The first picks the pole, the second inverts its radial CDF.

    Returns
    -------
    r : Array of shape ``S + C``
    """
    n = len(medium.shape)
    xi_pole = append_axes(as_float_array(xi_pole), n)
    xi = append_axes(as_float_array(xi_radius), n)
    z_r, z_v, sigma, p_real = _pole_choice(medium)
    z = jnp.where(xi_pole < p_real, z_r, z_v)
    eps = jnp.finfo(xi.dtype).eps
    log_one_minus = jnp.log1p(-jnp.clip(xi, 0.0, 1.0 - eps))
    t = _solve_log_u(sigma * z, log_one_minus)
    return z * jnp.sqrt(jnp.expm1(2 * t))


def dipole_pdf(medium: Medium, r):
    r""":math:`p(r) = 2\pi r R_d(r) / \rho` [1/mm], the density of :func:`sample_dipole_radius`."""
    r = as_float_array(r)
    return 2 * jnp.pi * append_axes(r, len(medium.shape)) * profile(medium, r) / total_reflectance(medium)


def dipole_cdf(medium: Medium, r):
    r"""Exact CDF of :func:`sample_dipole_radius`: per pole :math:`1 - e^{-\sigma z (u-1)}/u`."""
    r = append_axes(as_float_array(r), len(medium.shape))
    z_r, z_v, sigma, p_real = _pole_choice(medium)

    def pole(z):
        u = jnp.sqrt(1 + (r / z) ** 2)
        return 1 - jnp.exp(-sigma * z * (u - 1)) / u

    return p_real * pole(z_r) + (1 - p_real) * pole(z_v)


def mis_integrate(f, medium: Medium, key, n_samples: int, *, r_max):
    r"""Estimate :math:`\int_0^\infty 2\pi r f(r)\,dr` with two strategies and the balance heuristic.

    Strategy 1 draws radii from the dipole (:func:`sample_dipole_radius`), strategy 2
    uniformly over the disc of radius ``r_max`` (density :math:`2r/r_{max}^2`), ``n_samples``
    each; each sample is weighted by :math:`1/(p_1 + p_2)` (Veach's balance heuristic), so
    the estimate is unbiased wherever either strategy reaches, and robust when ``f`` differs
    from the dipole (Mertens et al. combine their strategies the same way).

    Parameters
    ----------
    f : callable
        ``f(r)`` for radii of shape ``(n,)``, returning ``(n,)`` (one channel).
    medium : Medium
        Scalar (one channel).
    key : jax.random key
    n_samples : int
    r_max : float [mm]

    Returns
    -------
    estimate, standard_error : Arrays (scalars)
    """
    if medium.shape != ():
        raise ValueError(f"mis_integrate needs a single-channel medium; got shape {medium.shape}.")
    k1, k2, k3 = jax.random.split(key, 3)
    r1 = sample_dipole_radius(medium, jax.random.uniform(k1, (n_samples,)), jax.random.uniform(k2, (n_samples,)))
    r2 = r_max * jnp.sqrt(jax.random.uniform(k3, (n_samples,)))

    def uniform_pdf(r):
        return jnp.where(r <= r_max, 2 * r / r_max**2, 0.0)

    def contribution(r):
        integrand = 2 * jnp.pi * r * f(r)
        density = dipole_pdf(medium, r) + uniform_pdf(r)
        positive = density > 0  # both vanish only at r = 0, where the integrand does too
        return jnp.where(positive, integrand / jnp.where(positive, density, 1.0), 0.0)

    values = jnp.concatenate([contribution(r1), contribution(r2)])
    # Each pair (one sample per strategy) is one unbiased estimate of the integral.
    pairs = values[:n_samples] + values[n_samples:]
    return jnp.mean(pairs), jnp.std(pairs) / np.sqrt(n_samples)
