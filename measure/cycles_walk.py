r"""A model of Blender Cycles' random-walk subsurface scattering, for choosing its inputs.

Cycles 4.x (``kernel/integrator/subsurface_random_walk.h`` and ``subsurface.h``, read in the
sources the bpy 4.5.15 wheel ships) turns a Principled BSDF's colour A and radius into a
medium and walks it, but not the medium jsss models:

- **index-matched exit**: a photon leaves at its first surface hit (no internal Fresnel
  reflection); the exit point is shaded as a Lambertian surface of albedo 1;
- **entry**: the camera ray refracts in through the (smooth, with roughness 0) surface, so
  at normal view the walk starts as a normally incident pencil beam, weighted by the
  specular layer's ``1 - F(0)``;
- **256 bounces at most** (``BSSRDF_MAX_BOUNCES``): a photon still inside after 255
  scatterings is lost;
- **albedo floor**: single-scattering albedos below 0.2 are walked at 0.2 with the
  throughput scaled by alpha / 0.2 once;
- **g**: after 9 bounces the walk continues in the similar isotropic medium,
  sigma_s* = sigma_s (1 - g).

So at normal view under a uniform white environment Cycles shows
:math:`F(0) + (1 - F(0))\,R_c(\alpha)`, with :math:`R_c` the total reflectance of that walk
per unit entering flux (:func:`walk_reflectance`), while the medium shows
:math:`F(0) + (1 - F(0))\,R_d` (the transport tables at the medium's eta). The export keeps
Cycles' mean free path and chooses the albedo with :math:`R_c(\alpha) = R_d`
(:func:`albedo_for_reflectance`): totals agree, profiles do not (see :mod:`measure.export`).

The model of :math:`R_c`
------------------------
:math:`R_c(\alpha) = w\,[R_1(\alpha_w) - \text{tail}(\alpha_w^*)]`, with
:math:`\alpha_w = \max(\alpha, 0.2)`, :math:`w = \min(\alpha / 0.2, 1)`:

- :math:`R_1` is the uncapped index-matched walk's total reflectance for a normally incident
  beam: :func:`jsss.transport.total_reflectance` at eta = 1 (within 0.2 % of Chandrasekhar's
  exact :math:`1 - H(1)\sqrt{1 - \alpha}` for g = 0: ``tests/measure/test_export.py``);
- the tail is what the bounce cap removes. Beyond a few tens of bounces the walk is the
  similar isotropic one (albedo :math:`\alpha^* = \alpha(1-g)/(1-\alpha g)`), whose exits
  after exactly n scatterings fall as :math:`P_n \simeq C n^{-3/2}`,
  :math:`C = H(1)/(2\sqrt\pi) = 0.8203` (the :math:`\sqrt{1-\alpha}` singularity of
  :math:`1 - H(1)\sqrt{1-\alpha}`), so
  :math:`\text{tail} = C\int_{255.5}^\infty \alpha^{*n} n^{-3/2}\,dn`. Against the exact
  orders of scattering it is 1 % high (about 3e-4 of R at marble's albedo): the cap costs
  marble 4 % of its light, which the chosen albedo gives back.

For g = 0 this is the walk exactly (Cycles renders of marble, ketchup and skin1 within 0.2 %:
``docs/benchmarks/exports.md``). For other g it is an approximation: :math:`R_1` is the
tables' walk, anisotropic throughout, where Cycles' turns isotropic after 9 bounces, and the
cap's tail is the similar walk's (g = 0.8: Cycles renders within 2 % but skin's red, 3.5 %
above); where the tables have no such g, :math:`R_1` is the g = 0 table at :math:`\alpha^*`.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import special

__all__ = ["BOUNCE_CAP_LENGTH", "MIN_ALBEDO", "TAIL_CONSTANT", "albedo_for_reflectance", "albedo_from_colour",
           "colour_from_albedo", "walk_reflectance"]

MIN_ALBEDO = 0.2          # subsurface_random_walk_coefficients: min_alpha
BOUNCE_CAP_LENGTH = 255.5  # photons leaving after 256 or more scatterings are lost (midpoint rule)
TAIL_CONSTANT = 2.90781 / (2 * np.sqrt(np.pi))  # H(1) of conservative isotropic scattering / (2 sqrt pi)
MAX_ALBEDO = 0.999999     # Cycles' clamp of alpha


def _fit_terms(g):
    """Cycles' fit (``subsurface_random_walk_remap``, after Chiang et al. 2016 and Wrenninge
    et al. for g) of single-scattering albedo against its colour A: six terms in g."""
    p = g ** np.arange(8)
    a = p @ [1.8260523782, -1.28451056436, -1.79904629312, 9.19393289202, -22.8215585862, 32.0234874259,
             -23.6264803333, 7.21067002658]
    b = 4.98511194385 + 0.127355959438 * np.exp(p[1:] @ [31.1491581433, -201.847017512, 841.576016723,
                                                         -2018.09288505, 2731.71560286, -1935.41424244, 559.009054474])
    c = p @ [1.09686102424, -0.394704063468, 1.05258115941, -8.83963712726, 28.8643230661, -46.8802913581,
             38.5402837518, -12.7181042538]
    d = p @ [0.496310210422, 0.360146581622, -2.15139309747, 17.8896899217, -55.2984010333, 82.065982243,
             -58.5106008578, 15.8478295021]
    e = 4.23190299701 + 0.00310603949088 * np.exp(p[1:] @ [76.7316253952, -594.356773233, 2448.8834203,
                                                           -5576.68528998, 7116.60171912, -4763.54467887, 1303.5318055])
    f = p @ [2.40602999408, -2.51814844609, 9.18494908356, -79.2191708682, 259.082868209, -403.613804597,
             302.85712436, -87.4370473567]
    return a, b, c, d, e, f


def albedo_from_colour(colour, g=0.0):
    """Cycles' single-scattering albedo for a random-walk colour A in [0, 1] (its forward map)."""
    a, b, c, d, e, f = _fit_terms(float(g))
    colour = np.clip(np.asarray(colour, dtype=float), 0.0, 1.0)
    blend = colour ** 0.25
    alpha = (1 - blend) * a * np.arctan(b * colour) ** c + blend * d * np.arctan(e * colour) ** f
    return np.clip(alpha, 0.0, MAX_ALBEDO)


def colour_from_albedo(alpha, g=0.0):
    """The colour A that Cycles maps to single-scattering albedo ``alpha`` (bisection, 1e-12).

    The forward map rises from 0 at A = 0 to Cycles' clamp 0.999999 (reached at A = 0.918 for
    g = 0, lower for larger g); an albedo at the clamp gives the smallest A that reaches it.
    """
    alpha = np.asarray(alpha, dtype=float)
    lo, hi = np.zeros_like(alpha), np.ones_like(alpha)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = albedo_from_colour(mid, g) < alpha
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return hi


def _tabulated(g) -> bool:
    from jsss import transport

    return bool(np.any(np.isclose(transport.table_info()["gs"], float(g), atol=1e-9)))


def _similar(alpha, g):
    """Reduced albedo of the similar isotropic medium: sigma_s' / (sigma_a + sigma_s')."""
    return alpha * (1 - g) / (1 - alpha * g)


def _cap_tail(alpha_star):
    r""":math:`C\int_{L}^\infty \alpha^n n^{-3/2} dn = C[2e^{-aL}/\sqrt L - 2\sqrt{\pi a}\,\mathrm{erfc}\sqrt{aL}]`,
    :math:`a = -\ln\alpha`: the light a conservative-limit walk would still return after the cap."""
    a = -np.log(np.clip(alpha_star, 1e-300, 1.0))
    length = BOUNCE_CAP_LENGTH
    return TAIL_CONSTANT * (2 * np.exp(-a * length) / np.sqrt(length)
                            - 2 * np.sqrt(np.pi * a) * special.erfc(np.sqrt(a * length)))


def _uncapped(alpha, g):
    """Total reflectance of the index-matched walk (normal incidence, per entering flux): the
    transport tables at eta = 1."""
    from jsss import Medium, transport

    alpha = np.asarray(alpha, float)
    if _tabulated(g):
        medium = Medium(1.0 - alpha, alpha * (1.0 - g), 1.0)  # sigma_t (1 - g) = 1: units of no matter
        return np.asarray(transport.total_reflectance(medium, g=float(g)), float)
    star = _similar(alpha, g)
    return np.asarray(transport.total_reflectance(Medium(1.0 - star, star, 1.0), g=0.0), float)


def walk_reflectance(alpha, g=0.0):
    r"""Total reflectance :math:`R_c` of Cycles' walk at single-scattering albedo ``alpha``.

    Per unit entering flux, for a normally incident beam into a half space (the model in the
    module docstring: index-matched exit, 256-bounce cap, albedo floor 0.2).

    Parameters
    ----------
    alpha : array_like
        Cycles' single-scattering albedo, in [0, 0.999999].
    g : float
        Henyey-Greenstein mean cosine (Subsurface Anisotropy).

    Returns
    -------
    ndarray of the shape of ``alpha``, dimensionless.
    """
    alpha = np.clip(np.asarray(alpha, float), 0.0, MAX_ALBEDO)
    walked = np.maximum(alpha, MIN_ALBEDO)
    weight = alpha / walked
    return weight * (_uncapped(walked, float(g)) - _cap_tail(_similar(walked, float(g))))


@functools.lru_cache(maxsize=16)
def _curve(g: float):
    """R_c on a grid dense in log(1 - alpha): (alpha, R_c), R_c increasing."""
    alpha = np.concatenate([np.linspace(0.0, MIN_ALBEDO, 41)[:-1],
                            1.0 - np.geomspace(1.0 - MIN_ALBEDO, 1.0 - MAX_ALBEDO, 2000)])
    return alpha, walk_reflectance(alpha, g)


def albedo_for_reflectance(reflectance, g=0.0):
    """The single-scattering albedo whose Cycles walk returns ``reflectance`` (inverse of
    :func:`walk_reflectance`; linear interpolation on 2040 nodes, in log(1 - alpha) above 0.2).

    Returns ``(alpha, reachable)``: a reflectance above the walk's largest (about 0.90 for
    g = 0, at alpha = 0.999999, the cap's doing) gives that alpha and ``reachable`` False.
    """
    alpha, curve = _curve(float(g))
    reflectance = np.asarray(reflectance, float)
    reachable = reflectance <= curve[-1]
    low = reflectance < curve[40]
    log_gap = np.interp(reflectance, curve[40:], np.log(1.0 - alpha[40:]))
    linear = reflectance / curve[40] * MIN_ALBEDO  # below the floor R_c is linear in alpha
    return np.where(low, linear, 1.0 - np.exp(log_gap)), reachable
