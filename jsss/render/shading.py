r"""The camera pass: diffused textures and a specular lobe turned into radiance, then tone mapping.

Exitance :math:`M` [W/mm^2] is the flux per area that has *left* the surface (the dipole's
:math:`R_d` already counts the light the boundary sends back in: with :math:`\sigma_a = 0`
its total is 1). It is spread over outgoing directions by the exit Fresnel transmittance,
normalised so that exactly :math:`M` leaves:

.. math:: L_d(\theta_o) = \frac{F_t(\cos\theta_o, \eta)}{\pi\,T_{dr}(\eta)}\,M,
          \qquad T_{dr} = \int_0^1 F_t(\mu, \eta)\,2\mu\,d\mu = 1 - F_{dr,ext},
          \qquad \int_{2\pi} L_d\cos\theta_o\,d\omega_o = M,

with :math:`\theta_o` measured *outside* (:func:`jsss.fresnel.diffuse_fresnel_transmittance`).
The normalisation is the *external* one. Dividing by the internal :math:`1 - F_{dr}(\eta)`
(the dipole's boundary term) instead releases :math:`\eta^2 M`, because
:math:`\eta^2\cos\theta\,d\omega` is invariant under refraction and so
:math:`T_{dr} = \eta^2 (1 - F_{dr})`: 2.25 times the light that entered at :math:`\eta = 1.5`.
``tests/jsss/render/test_energy.py`` checks this with a furnace, where a non-absorbing
medium must return exactly the flux that entered, for every method.

(Jensen's :math:`S_d = F_t R_d F_t / \pi` leaves out the normalisation and loses the
fraction :math:`F_{dr,ext}` a second time, though the dipole's boundary condition has
already counted it.) The specular lobe is a microfacet BRDF with the Beckmann
distribution and exact dielectric Fresnel reflectance, as d'Eon uses for skin.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..fresnel import exit_lobe, fresnel_reflectance
from ..numerics import interpolate_rows
from ..diffusion.incidence import deposit_depth
from ..diffusion.single_scattering import single_scattering_albedo, single_scattering_brdf_from_cosines
from .environment import EnvironmentGeometry, environment_irradiance, environment_specular
from .lighting import depth_falloff

__all__ = ["angular_exit_lobe", "diffuse_radiance", "exit_weights", "frame_radiance", "single_scattering", "specular_radiance", "surface_radiance",
           "tone_map"]


def diffuse_radiance(exitance, cos_view, eta):
    r"""Radiance [W/(mm^2 sr)] of exitance ``exitance`` (..., C) seen at ``cos_view`` (...).

    ``cos_view`` is the cosine outside the surface; ``eta`` (C,) the relative index. Over
    the hemisphere :math:`\int L \cos\theta\,d\omega` is ``exitance`` exactly.
    """
    return exitance * exit_lobe(jnp.asarray(cos_view)[..., None], eta)


def exit_weights(law, light_geometry, radiant, eta):
    """The incidence-node weights (..., C, K) of the light arriving at each point, for
    :meth:`~jsss.diffusion.exit_law.ExitLaw.lobe`; None when no light is given (uniform light).

    ``law`` an :class:`~jsss.diffusion.exit_law.ExitLaw` (its weights depend on eta alone);
    ``light_geometry`` the lights at the points (:class:`~jsss.render.lighting.LightGeometry` or
    :class:`~jsss.render.environment.EnvironmentGeometry`), ``radiant`` (L, C) their colour times
    intensity, ``eta`` (C,). Each light weighs in with the flux it sends into the point; an
    environment as uniform light."""
    weights = None
    for i, g in enumerate(light_geometry):
        if isinstance(g, EnvironmentGeometry):
            term = environment_irradiance(g, radiant[i], eta)[..., None] * law.uniform
        else:
            cos = jnp.clip(g.cosine, 0.0, 1.0)
            term = law.weights(cos, radiant[i] * (cos * g.falloff * g.visible)[..., None])
        weights = term if weights is None else weights + term
    return weights


def angular_exit_lobe(law, cos_view, light_geometry, radiant, eta):
    r"""The exit lobe [1/sr] (..., C) of Chandrasekhar's kernel (:mod:`jsss.diffusion.exit_law`)
    for the light arriving at each point (:func:`exit_weights`): in place of
    :func:`jsss.fresnel.exit_lobe`. ``cos_view`` (...) is the exit cosine outside; a point no
    light reaches directly takes uniform light's lobe.
    """
    return law.lobe(jnp.asarray(cos_view), exit_weights(law, light_geometry, radiant, eta))


ALBEDO_NODES = 129  # cosines on which the single-scattering albedo is tabulated per frame


def single_scattering(medium, normals, view_dirs, light_geometry, radiant, *, deposit=None):
    r"""Single-scattered radiance toward the eye and exitance (both (..., C)), summed over lights.

    Jensen 2001 sec. 2.2 under a locally flat surface:

    .. math:: L^{(1)} = \sum_l f_r^{(1)}(\omega_l, \omega_o)\,E_l, \qquad
              M^{(1)} = \sum_l \rho^{(1)}(\theta_l)\,E_l, \qquad
              E_l = I_l\,c_l\cos\theta_l\,V_l / d_l^p,

    with the single-scattering BRDF :math:`f_r^{(1)}` and its hemispherical albedo
    :math:`\rho^{(1)}` of :mod:`jsss.diffusion.single_scattering` (HG with ``g = 0`` on the reduced
    coefficients, the model the dipole's medium is given in). It leaves within a mean free
    path of where light entered, so both are evaluated at the pixel's own point.

    :math:`\rho^{(1)}` depends on :math:`\cos\theta_l` alone: it is evaluated on
    ``ALBEDO_NODES`` cosines and interpolated linearly (within 2e-5 of its maximum for the
    Jensen materials, where the 16-node quadrature per pixel took 200 ms of a 320 x 240 frame).
    With ``deposit`` (a Medium) point lights are read at its deposit depth
    (:func:`jsss.render.lighting.depth_falloff`).
    """
    n = jnp.asarray(normals, radiant.dtype)
    v = jnp.asarray(view_dirs, radiant.dtype)
    cos_o = jnp.clip((n * v).sum(-1), 0.0, 1.0)
    nodes = jnp.linspace(0.0, 1.0, ALBEDO_NODES, dtype=radiant.dtype)
    albedo_table = single_scattering_albedo(medium, nodes, nodes=16)  # (ALBEDO_NODES, C)
    radiance, exitance = 0.0, 0.0
    for i, g in enumerate(light_geometry):
        if isinstance(g, EnvironmentGeometry):
            r, m = _environment_single_scattering(medium, g, n, v, cos_o, radiant[i], albedo_table)
            radiance, exitance = radiance + r, exitance + m
            continue
        to_light = jnp.asarray(g.to_light, radiant.dtype)
        cos_i = jnp.clip((n * to_light).sum(-1), 0.0, 1.0)
        arriving = (cos_i * jnp.asarray(g.falloff * g.visible, radiant.dtype))[..., None] * radiant[i]
        if deposit is not None:
            arriving = arriving * depth_falloff(g, deposit_depth(deposit), radiant.dtype)
        tangential = (to_light * v).sum(-1) - cos_i * cos_o
        radiance = radiance + single_scattering_brdf_from_cosines(medium, cos_i, cos_o, tangential) * arriving
        exitance = exitance + _albedo_at(albedo_table, cos_i) * arriving
    return radiance, exitance


def _albedo_at(albedo_table, cos_i):
    return interpolate_rows(cos_i * (ALBEDO_NODES - 1), albedo_table)


def _environment_single_scattering(medium, g, n, v, cos_o, radiant, albedo_table):
    """An environment's first bounce: its cells (:func:`jsss.render.environment.scattering_cells`)
    as parallel lights, summed in a ``scan`` (one cell's arrays at a time), each times the
    point's visible share."""
    seen = jnp.asarray(g.visible, radiant.dtype)[..., None] * radiant

    def cell(carry, item):
        direction, power = item
        cos_i = jnp.clip((n * direction).sum(-1), 0.0, 1.0)
        arriving = cos_i[..., None] * power * seen
        tangential = (direction * v).sum(-1) - cos_i * cos_o
        radiance = carry[0] + single_scattering_brdf_from_cosines(medium, cos_i, cos_o, tangential) * arriving
        return (radiance, carry[1] + _albedo_at(albedo_table, cos_i) * arriving), None

    zero = jnp.zeros(n.shape[:-1] + (radiant.shape[-1],), radiant.dtype)
    (radiance, exitance), _ = jax.lax.scan(cell, (zero, zero), (g.cell_directions, g.cell_power))
    return radiance, exitance


def frame_radiance(exitance, exit_lobe, coverage=None, *, single_scattering=None, specular=None):
    r"""A frame's radiance from its parts: the one place they are put together.

    .. math:: L = c\,\bigl(\max(M - M^{(1)}, 0)\,\Lambda + L^{(1)} + L_s\bigr)

    Parameters
    ----------
    exitance : array (..., C) [W/mm^2]
        Diffusion exitance :math:`M` of each point.
    exit_lobe : array (..., C) [1/sr]
        Radiance per unit exitance toward the eye, :math:`\Lambda` (:func:`jsss.fresnel.exit_lobe`).
    coverage : array (...), optional
        Share :math:`c` of each pixel the surface covers (default: 1).
    single_scattering : pair of arrays (..., C), optional, keyword-only
        Single-scattered radiance :math:`L^{(1)}` [W/(mm^2 sr)] and exitance :math:`M^{(1)}`
        [W/mm^2] (:func:`single_scattering`). The dipole's source already holds every order of
        scattering, so the first bounce *replaces* its share of the diffusion light (never
        below zero; :func:`surface_radiance`). Without it :math:`\max(M, 0)` is spread.
    specular : array (..., C), optional, keyword-only
        The surface reflection :math:`L_s` [W/(mm^2 sr)] (:func:`specular_radiance`).
    """
    if single_scattering is None:
        # Light leaving is never negative; a sum of Gaussians fitted with negative weights (a
        # layered profile's) dips below zero where little light is left (-3e-5 in the back-lit
        # skin example's blue, against a peak of 0.1)
        radiance = jnp.maximum(exitance, 0.0) * exit_lobe
    else:
        single_radiance, single_exitance = single_scattering
        radiance = jnp.maximum(exitance - single_exitance, 0.0) * exit_lobe + single_radiance
    if specular is not None:
        radiance = radiance + specular
    return radiance if coverage is None else radiance * coverage[..., None]


def surface_radiance(exitance, cos_view, eta, *, medium=None, normals=None, view_dirs=None, light_geometry=(),
                     radiant=None, deposit=None):
    """Diffuse radiance of ``exitance``; with ``medium`` given, single scattering takes its share.

    The dipole's source already holds every order of scattering (with ``sigma_a = 0`` its total
    is 1), so single scattering *replaces* its share of the diffusion light instead of adding
    to it: adding would return 1.07 times the light that entered at albedo 0.999, eta = 1.
    The diffusion exitance keeps what single scattering does not return (never below zero),
    spread by :func:`diffuse_radiance`, plus the single-scattered radiance: the frame's total
    flux is the diffusion model's, its angular law exact for the first bounce
    (:func:`frame_radiance`).
    """
    single = None
    if medium is not None:
        single = single_scattering(medium, normals, view_dirs, light_geometry, radiant, deposit=deposit)
    return frame_radiance(exitance, exit_lobe(jnp.asarray(cos_view)[..., None], eta), single_scattering=single)


def specular_radiance(normals, view_dirs, light_geometry, radiant, eta, *, roughness, weight):
    """Sum over lights of a Beckmann microfacet lobe (Cook-Torrance), (..., C); an environment's
    reflection by :func:`jsss.render.environment.environment_specular`.

    Parameters
    ----------
    normals, view_dirs : array (..., 3)
        Unit normal and unit direction from the surface to the eye.
    light_geometry : list of LightGeometry (per pixel)
    radiant : array (L, C)
    eta : array (C,)
    roughness : float, Beckmann slope RMS m
    weight : float, scales the lobe (1 = physically based)
    """
    n = jnp.asarray(normals, radiant.dtype)
    v = jnp.asarray(view_dirs, radiant.dtype)
    cos_o = jnp.clip((n * v).sum(-1), 1e-4, 1.0)
    total = 0.0
    for i, g in enumerate(light_geometry):
        if isinstance(g, EnvironmentGeometry):
            total = total + environment_specular(g, normals, view_dirs, radiant[i], eta, roughness=roughness,
                                                 weight=weight)
            continue
        to_light = jnp.asarray(g.to_light, radiant.dtype)
        cos_i = jnp.clip((n * to_light).sum(-1), 0.0, 1.0)
        h = to_light + v
        h = h / jnp.maximum(jnp.linalg.norm(h, axis=-1, keepdims=True), 1e-9)
        cos_h = jnp.clip((n * h).sum(-1), 1e-4, 1.0)
        tan2 = (1 - cos_h**2) / cos_h**2
        m2 = roughness**2
        D = jnp.exp(-tan2 / m2) / (jnp.pi * m2 * cos_h**4)
        vh = jnp.clip((v * h).sum(-1), 1e-4, 1.0)
        G = jnp.minimum(1.0, jnp.minimum(2 * cos_h * cos_o / vh, 2 * cos_h * cos_i / vh))
        F = fresnel_reflectance(vh[..., None], eta)
        brdf = F * (D * G / (4 * cos_o))[..., None]  # times cos_i below cancels its own
        irr = (jnp.asarray(g.falloff * g.visible, radiant.dtype))[..., None] * radiant[i]
        total = total + weight * brdf * irr * (cos_i > 0)[..., None]
    return total


def tone_map(radiance, *, exposure=None, percentile: float = 99.0):
    """Linear radiance to display sRGB in [0, 1] (NumPy; not on the differentiable path).

    ``exposure`` scales radiance before the sRGB curve; by default it maps the given
    percentile of the non-zero pixels' brightest channel to 1.
    """
    x = np.asarray(radiance, float)
    if exposure is None:
        peak = x.max(-1)
        lit = peak[peak > 0]
        exposure = 1.0 / np.percentile(lit, percentile) if lit.size else 1.0
    x = np.clip(x * exposure, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055), float(exposure)
