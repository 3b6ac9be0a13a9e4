r"""Single scattering under a flat surface (Jensen et al. 2001 sec. 2.2 and 2.4).

Directions are unit 3-vectors in the local frame of the surface, normal along +z,
both pointing *away* from the surface (towards the light and towards the viewer).
The medium's single-scattering coefficients follow from the reduced ones and the
Henyey-Greenstein asymmetry ``g``: :math:`\sigma_s = \sigma_s' / (1 - g)`,
:math:`\sigma_t = \sigma_a + \sigma_s`, albedo :math:`\alpha = \sigma_s/\sigma_t`.

Batch shapes: directions of shape ``S + (3,)`` with a medium of shape ``C`` give
results of shape ``S + C``.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..fresnel import fresnel_transmittance, refracted_cosine
from . import dipole
from ..medium import Medium
from ..numerics import append_axes, as_float_array, is_concrete, safe_sqrt

__all__ = [
    "henyey_greenstein",
    "single_scattering",
    "single_scattering_albedo",
    "single_scattering_share",
    "single_scattering_brdf",
    "single_scattering_brdf_from_cosines",
]


def henyey_greenstein(cos_theta, g):
    r"""Henyey-Greenstein phase function, normalised over the sphere [1/sr].

    .. math:: p(\cos\theta) = \frac{1}{4\pi}\frac{1 - g^2}{(1 + g^2 - 2 g\cos\theta)^{3/2}}

    ``cos_theta`` is the cosine between the propagation directions before and after
    scattering, so ``g > 0`` scatters forward. ``g`` in (-1, 1); ``g = 0`` is isotropic.
    """
    cos_theta = as_float_array(cos_theta)
    denom = 1 + g**2 - 2 * g * cos_theta
    return (1 - g**2) / (4 * jnp.pi * denom * jnp.sqrt(denom))


def _check_g(g):
    if is_concrete(g):
        value = np.asarray(g, dtype=float)
        if not np.all(np.isfinite(value)) or np.any(np.abs(value) >= 1):
            raise ValueError(
                f"g (the Henyey-Greenstein mean cosine) must lie in (-1, 1); got {g!r}."
            )


def _geometry(medium, omega_i, omega_o):
    """Refracted cosines, the phase-angle cosine and the Fresnel product F = Ft_i Ft_o."""
    omega_i = as_float_array(omega_i)
    omega_o = as_float_array(omega_o)
    tangential_dot = jnp.sum(omega_i[..., :2] * omega_o[..., :2], axis=-1)
    return _geometry_from_cosines(medium, omega_i[..., 2], omega_o[..., 2], tangential_dot)


def _geometry_from_cosines(medium, cos_i, cos_o, tangential_dot):
    n = len(medium.shape)
    cos_i, cos_o, tangential_dot = (append_axes(as_float_array(a), n) for a in (cos_i, cos_o, tangential_dot))
    eta = medium.eta
    cos_i_in = refracted_cosine(cos_i, eta)
    cos_o_in = refracted_cosine(cos_o, eta)
    # Propagation inside: incoming travels (-w_i,xy / eta, -cos_i'), outgoing (w_o,xy / eta, cos_o').
    cos_phase = -tangential_dot / eta**2 - cos_i_in * cos_o_in
    fresnel = fresnel_transmittance(cos_i, eta) * fresnel_transmittance(cos_o, eta)
    return cos_i_in, cos_o_in, cos_phase, fresnel


def _coefficients(medium, g):
    sigma_s = medium.sigma_s_prime / (1 - g)
    sigma_t = medium.sigma_a + sigma_s
    return sigma_s, sigma_t


def single_scattering(medium: Medium, s, omega_i, omega_o, *, g=0.0):
    r"""Integrand of Jensen eq. 6: single-scattered radiance per unit path length.

    Light refracts in along :math:`\omega_i'`, scatters once at distance ``s`` along
    the refracted outgoing ray, and leaves along :math:`\omega_o`. For a flat surface
    the incoming path inside is :math:`s\,G` with :math:`G = |n\cdot\omega_o'|/|n\cdot\omega_i'|`, so

    .. math:: \frac{dL_o}{ds} = \sigma_s\,F\,p(\omega_i'\cdot\omega_o')\,e^{-\sigma_{t}(1 + G) s}\,L_i

    with :math:`F = F_t(\eta,\omega_i)F_t(\eta,\omega_o)`, divided by :math:`\eta^2` for the
    radiance leaving (see :func:`single_scattering_brdf`; Jensen's eq. 6 omits it). Returned
    per unit incident radiance, in 1/mm/sr.

    Parameters
    ----------
    medium : Medium
    s : array_like, mm
        Distance along the refracted outgoing ray, >= 0; broadcast against the batch
        shape of the directions.
    omega_i, omega_o : array_like, shape ``S + (3,)``
        Unit directions away from the surface (z > 0).
    g : float, keyword-only
        Henyey-Greenstein mean cosine in (-1, 1).
    """
    _check_g(g)
    cos_i_in, cos_o_in, cos_phase, fresnel = _geometry(medium, omega_i, omega_o)
    sigma_s, sigma_t = _coefficients(medium, g)
    geometry_factor = cos_o_in / cos_i_in
    s = append_axes(as_float_array(s), len(medium.shape))
    attenuation = jnp.exp(-sigma_t * (1 + geometry_factor) * s)
    return sigma_s * fresnel * henyey_greenstein(cos_phase, g) * attenuation / jnp.square(medium.eta)


def single_scattering_brdf(medium: Medium, omega_i, omega_o, *, g=0.0):
    r"""Single-scattering BRDF of a semi-infinite medium (Hanrahan & Krueger; Jensen sec. 2.4).

    .. math:: f_r^{(1)} = \frac{\alpha\,F}{\eta^2}\,
              \frac{p(\omega_i'\cdot\omega_o')}{|n\cdot\omega_i'| + |n\cdot\omega_o'|}

    the integral of :func:`single_scattering` over ``s`` divided by
    :math:`|n\cdot\omega_i'|`, and by :math:`\eta^2` for the radiance leaving: radiance over
    :math:`n^2` is what refraction conserves, so light inside of radiance :math:`L'` leaves
    with :math:`F_t L'/\eta^2` (flux balance: :math:`\cos\theta_o\,d\omega_o =
    \eta^2\cos\theta_o'\,d\omega_o'`). Jensen's eq. 7 and its BRDF form omit the
    :math:`1/\eta^2`, which returns :math:`\eta^2` times the single-scattered light that
    transport gives: ``tests/jsss/test_single_scattering.py`` checks the form used here
    against a Monte Carlo walk stopped after its first collision (0.0382 +- 0.0003
    against 0.0379 at albedo 0.5, eta 1.3; Jensen's form 0.064). Units 1/sr.
    """
    omega_i = as_float_array(omega_i)
    omega_o = as_float_array(omega_o)
    tangential_dot = jnp.sum(omega_i[..., :2] * omega_o[..., :2], axis=-1)
    return single_scattering_brdf_from_cosines(medium, omega_i[..., 2], omega_o[..., 2], tangential_dot, g=g)


def single_scattering_brdf_from_cosines(medium: Medium, cos_i, cos_o, tangential_dot, *, g=0.0):
    """:func:`single_scattering_brdf` from the frame-free quantities a renderer has per point.

    ``cos_i = n . w_i``, ``cos_o = n . w_o`` and ``tangential_dot = w_i . w_o - cos_i cos_o``
    (the dot product of the two directions' tangential parts); shapes ``S``, result ``S + C``.
    """
    _check_g(g)
    cos_i_in, cos_o_in, cos_phase, fresnel = _geometry_from_cosines(medium, cos_i, cos_o, tangential_dot)
    sigma_s, sigma_t = _coefficients(medium, g)
    albedo = sigma_s / sigma_t
    # At eta = 1 both refracted cosines vanish together at grazing incidence and exit (the
    # background pixels of a frame, where normals are zero): 1 / (cos_i' + cos_o') is infinite
    # there, and the radiance it meets is multiplied by cos_i = 0. The BRDF is set to 0 on that
    # set, with the double where that keeps its gradient finite too.
    path = cos_i_in + cos_o_in
    grazing = path <= 0
    safe_path = jnp.where(grazing, 1.0, path)
    value = albedo * fresnel * henyey_greenstein(cos_phase, g) / (safe_path * jnp.square(medium.eta))
    return jnp.where(grazing, 0.0, value)


@partial(jax.jit, static_argnames=("g", "nodes"))  # one program: op by op, 2.2 s per call (render planning)
def single_scattering_albedo(medium: Medium, cos_incident=1.0, *, g=0.0, nodes: int = 48):
    r"""Single-scattered flux leaving per unit flux *arriving* from direction ``cos_incident``.

    :math:`\int_{2\pi} f_r^{(1)}(\omega_i, \omega_o)\cos\theta_o\,d\omega_o` by Gauss-Legendre
    quadrature in :math:`\cos\theta_o` (``nodes``) and, for ``g != 0``, in azimuth. Includes
    the Fresnel loss at entry and at exit. Shape: ``cos_incident``'s shape + ``medium.shape``.
    """
    cos_incident = as_float_array(cos_incident)
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu = jnp.asarray((x + 1) / 2, cos_incident.dtype)
    weights = jnp.asarray(w / 2, cos_incident.dtype)
    n_phi = 1 if g == 0 else 32
    phi = jnp.asarray((np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi, cos_incident.dtype)
    sin_i = safe_sqrt(jnp.clip(1 - cos_incident**2, 0.0, 1.0))[..., None, None]
    sin_o = jnp.sqrt(1 - mu**2)[:, None]
    # Directions (sin_i, 0, cos_i) and (sin_o cos phi, sin_o sin phi, mu): tangential dot sin_i sin_o cos phi.
    f = single_scattering_brdf_from_cosines(medium, cos_incident[..., None, None], mu[:, None],
                                            sin_i * sin_o * jnp.cos(phi), g=g)  # (..., nodes, n_phi) + C
    n = len(medium.shape)
    quad = append_axes(mu * weights, n)[:, None] * (2 * jnp.pi / n_phi)
    return (f * quad).sum((-2 - n, -1 - n))


def single_scattering_share(medium) -> np.ndarray:
    """Single-scattered light over all the light leaving, per channel, under light along the normal.

    Both per unit flux arriving: :func:`single_scattering_albedo` over
    the dipole's total times the entry transmittance. A medium of numbers (the planner's) is
    done in NumPy (``_single_and_diffuse_numpy``, equal to 1e-13 in float64): tracing and
    lowering the JAX program was 0.2 s of planning each new process.
    """
    pair = _single_and_diffuse_numpy(medium) if is_concrete(medium) else _single_and_diffuse(medium)
    single, diffusion = (np.asarray(a) for a in pair)
    return single / np.maximum(diffusion, 1e-300)


def _single_and_diffuse_numpy(medium):
    """:func:`_single_and_diffuse` step by step in NumPy (g = 0, 48 nodes, light along the
    normal), in the dtype JAX computes it in. The formulas are those of
    :func:`single_scattering_brdf_from_cosines`, :func:`jsss.fresnel.fresnel_reflectance`,
    :func:`jsss.fresnel.diffuse_fresnel_reflectance` and :func:`jsss.diffusion.dipole.total_reflectance`;
    ``tests/jsss/test_planner_numpy_paths.py`` holds them equal."""
    sigma_a, sigma_s_prime, eta = (np.asarray(x) for x in (medium.sigma_a, medium.sigma_s_prime, medium.eta))
    dtype = np.result_type(jax.dtypes.canonicalize_dtype(np.float64), sigma_a, sigma_s_prime, eta)
    sigma_a, sigma_s_prime, eta = (x.astype(dtype) for x in (sigma_a, sigma_s_prime, eta))
    n = len(np.broadcast_shapes(sigma_a.shape, sigma_s_prime.shape, eta.shape))

    def transmittance(cos):  # 1 - fresnel_reflectance(cos, eta), its double where included
        cos_t = np.sqrt(np.maximum(1 - (1 - cos**2) / np.square(eta), 0))
        total_internal = (1 - cos**2) >= np.square(eta)
        rs_den, rp_den = cos + eta * cos_t, eta * cos + cos_t
        ok = (rs_den > 0) & (rp_den > 0) & ~total_internal
        rs = (cos - eta * cos_t) / np.where(ok, rs_den, 1.0)
        rp = (eta * cos - cos_t) / np.where(ok, rp_den, 1.0)
        return 1 - np.where(ok, 0.5 * (rs**2 + rp**2), 1.0)

    x, w = np.polynomial.legendre.leggauss(48)
    mu, weights = ((x + 1) / 2).astype(dtype), (w / 2).astype(dtype)
    cos_i, cos_o = np.ones((1, 1) + (1,) * n, dtype), mu.reshape((-1, 1) + (1,) * n)
    cos_i_in = np.sqrt(np.maximum(1 - (1 - cos_i**2) / np.square(eta), 0))
    cos_o_in = np.sqrt(np.maximum(1 - (1 - cos_o**2) / np.square(eta), 0))
    phase = 1 / (4 * np.pi)  # henyey_greenstein at g = 0, whatever the phase angle
    albedo = sigma_s_prime / (sigma_a + sigma_s_prime)
    path = cos_i_in + cos_o_in
    grazing = path <= 0
    brdf = albedo * transmittance(cos_i) * transmittance(cos_o) * phase / (np.where(grazing, 1.0, path) * np.square(eta))
    brdf = np.where(grazing, 0.0, brdf)
    quad = (mu * weights).reshape((-1,) + (1,) * n)[:, None] * (2 * np.pi)
    single = (brdf * quad).sum((-2 - n, -1 - n))
    # dipole.total_reflectance times the entry transmittance along the normal.
    sigma_t = sigma_a + sigma_s_prime
    safe_eta = np.where(eta > 0, eta, 1.0)
    fdr = np.where(eta >= 1, -1.440 / safe_eta**2 + 0.710 / safe_eta + 0.668 + 0.0636 * safe_eta,
                   -0.4400 + 0.7099 / safe_eta - 0.3319 / safe_eta**2 + 0.0636 / safe_eta**3)
    z_r = 1.0 / sigma_t
    z_v = z_r + 4.0 * ((1 + fdr) / (1 - fdr)) * (1.0 / (3.0 * sigma_t))
    sigma_tr = np.sqrt(np.maximum(3.0 * sigma_a * sigma_t, 0))
    reduced = np.where(sigma_t > 0, sigma_s_prime / np.where(sigma_t > 0, sigma_t, 1.0), 0.0)
    total = 0.5 * reduced * (np.exp(-sigma_tr * z_r) + np.exp(-sigma_tr * z_v))
    return single, total * transmittance(np.ones((), dtype))


@jax.jit  # one program (op by op it was 0.9 s of planning a render)
def _single_and_diffuse(medium):
    return (single_scattering_albedo(medium, jnp.asarray(1.0)),
            dipole.total_reflectance(medium) * fresnel_transmittance(jnp.asarray(1.0), medium.eta))
