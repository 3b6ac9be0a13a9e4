r"""Where the light leaving toward a direction was last scattered: the lateral step of the last leg.

A half space lit at a point returns light around it (the profile), and the renderer reads the
light that leaves a surface point toward the camera from the exitance *at* that point. But the
light leaving toward the camera at the inner cosine :math:`\mu` crossed the last stretch below
the surface along the refracted view ray: it was last scattered at an optical depth
:math:`\tau` under a point a lateral :math:`\tau\tan\theta/\sigma_t'` farther from the camera.
Wherever the light changes over a few transport mean free paths (near a lamp, at a shadow's or
a plane's edge, at an albedo map's edges) the camera sees the exitance of that farther point.

**The mean depth.** The emergent intensity of a plane-parallel medium is the Laplace transform
of its source function, :math:`I(0, \mu) = \hat J(1/\mu)/\mu`, so with :math:`I(0,\mu) \propto
K(\mu)` the mean optical depth of the last scattering is

.. math:: \langle\tau\rangle(\mu) = -\frac{d\ln\hat J(s)}{ds}\Big|_{s=1/\mu}
          = \mu + \mu^2\,\frac{K'(\mu)}{K(\mu)},

and for Chandrasekhar's kernel of isotropic scattering (Chandrasekhar 1960, eq. IV.(29);
:mod:`.exit_law`) :math:`K = (H(\mu_0)H(\mu) - s)/(\mu_0 + \mu)`, with :math:`s = 1` when the
first bounce is counted apart:

.. math:: \langle\tau\rangle = \frac{\mu\mu_0}{\mu + \mu_0}
          + \mu^2\,\frac{H(\mu_0)\,H'(\mu)}{H(\mu_0)H(\mu) - s},\qquad
          \Delta_{\rm exit} = \frac{\sqrt{1-\mu^2}}{\mu}\,\frac{\langle\tau\rangle}{\sigma_t'}
          \;[\mathrm{mm}].

At albedo 0 (:math:`H = 1`, :math:`s = 0`) this is single scattering's
:math:`\mu\mu_0/(\mu+\mu_0)`. :math:`H'` comes from differentiating the H equation:
:math:`H'(\mu) = H(\mu)^2\,(\omega/2)\sum_j w_j\mu_j H(\mu_j)/(\mu+\mu_j)^2`.

**Both legs.** With isotropic scattering every middle leg's azimuth is uniform whatever the
depths, so the mean displacement from entry to exit is the first leg's, along the light, plus
the last leg's, toward the camera. The kernel is symmetric (reciprocity), so the first leg's
mean step is the same formula with :math:`\mu` and :math:`\mu_0` swapped
(:func:`first_leg_step`). ``tests/jsss/test_lateral_step.py`` checks both against an
independent random walk (NumPy, no jsss).

Exact for isotropic scattering at eta 1 in the similarity coefficients
:math:`\sigma_t' = \sigma_a + \sigma_s'`; behind a Fresnel boundary the cosines are the
refracted ones and the boundary's internal reflections, which this leaves out, make the light
a little more diffuse. The renderer's pass "last leg" (:mod:`jsss.render.last_leg`) reads the
light there; measured against Mitsuba on the ketchup plane (``benchmarks/lateral_exit.py``) it
takes red from 7.2 to 2.6 % per pixel.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..fresnel import refracted_cosine
from ..medium import Medium
from ..numerics import as_float_array, safe_sqrt
from .incidence import _nodes, h_function, largest_albedo

__all__ = ["first_leg_step", "last_leg_step"]

SMALLEST_COSINE = 1e-6  # the step's tan(theta) <tau> tends to 1/sigma_t' at grazing: the cosine is held above 0


def _h_and_slope(albedo, mu):
    """H and dH/dmu at ``mu`` (shape ``S + C``), from H on the Gauss-Legendre nodes (Nystrom)."""
    dtype = mu.dtype
    nodes, weights = _nodes(dtype)
    terms = weights * nodes * jnp.moveaxis(h_function(albedo, nodes), 0, -1)  # C + (J,): w_j mu_j H(mu_j)
    apart = mu[..., None] + nodes                                          # S + C + (J,)
    sums = (terms / apart).sum(-1)
    slope_sums = (terms / apart**2).sum(-1)
    root = safe_sqrt(jnp.maximum(1 - albedo, 0.0))
    h = 1.0 / (root + albedo / 2 * sums)
    return h, h**2 * (albedo / 2) * slope_sums


def _step(medium: Medium, cos_from, cos_to, first_bounce_apart: bool):
    """Mean lateral step [mm] of the leg at the (outside) cosine ``cos_to``, the other leg at
    ``cos_from``: shape ``S + (C,)``."""
    sigma_a, sigma_s = as_float_array(medium.sigma_a), as_float_array(medium.sigma_s_prime)
    sigma_t = jnp.atleast_1d(sigma_a + sigma_s)
    dtype = sigma_t.dtype
    albedo = largest_albedo(jnp.atleast_1d(sigma_s) / sigma_t, dtype)
    eta = jnp.broadcast_to(jnp.asarray(medium.eta, dtype), sigma_t.shape)
    outside_to = jnp.clip(jnp.asarray(cos_to, dtype), 0.0, 1.0)[..., None]
    outside_from = jnp.clip(jnp.asarray(cos_from, dtype), 0.0, 1.0)[..., None]
    mu = jnp.maximum(refracted_cosine(outside_to, eta), SMALLEST_COSINE)        # S + (C,)
    mu0 = jnp.maximum(refracted_cosine(outside_from, eta), SMALLEST_COSINE)
    h, slope = _h_and_slope(albedo, mu)
    h0, _ = _h_and_slope(albedo, mu0)
    s = 1.0 if first_bounce_apart else 0.0
    returned = h0 * h - s
    # Albedo 0 with the first bounce apart returns nothing: 0/0, whose limit is the ratio of the
    # slopes' leading terms; any finite value is multiplied by nothing that reaches the camera.
    ok = returned > 1e-12
    ratio = jnp.where(ok, h0 * slope / jnp.where(ok, returned, 1.0), 0.0)
    sine = safe_sqrt(jnp.maximum(1 - mu**2, 0.0))
    return sine * (mu0 / (mu + mu0) + mu * ratio) / sigma_t


def last_leg_step(medium: Medium, cos_incident, cos_exit, *, first_bounce_apart: bool = False):
    r"""Mean lateral step [mm] of the light's last leg below the surface, toward the camera.

    ``cos_incident``, ``cos_exit``: outside cosines of the light and the view (broadcast to
    shape ``S``); the result has shape ``S + (C,)``. The light that leaves toward the camera was
    last scattered, on average, this far from the exit point *away from the camera* (the module
    docstring derives :math:`\Delta_{\rm exit}`). ``first_bounce_apart``: the multiply
    scattered light's step (the single-scattering pass renders the first bounce apart). In the
    medium's dtype; differentiable in its coefficients.
    """
    return _step(medium, cos_incident, cos_exit, first_bounce_apart)


def first_leg_step(medium: Medium, cos_incident, cos_exit, *, first_bounce_apart: bool = False):
    r"""Mean lateral step [mm] of the light's first leg, along the incident light's tangential
    direction (away from the light), for the light that leaves at ``cos_exit``: by
    reciprocity :func:`last_leg_step` with the two cosines swapped."""
    return _step(medium, cos_exit, cos_incident, first_bounce_apart)
