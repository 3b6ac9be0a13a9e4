r"""At which angle the multiply scattered light of a half space leaves: Chandrasekhar's exit law.

The diffusion exit law (:func:`jsss.fresnel.exit_lobe`) spreads a point's exitance :math:`M`
as if the radiance inside were isotropic: :math:`L/M = F_t(\mu)/(\pi T_{dr})`. For an
index-matched half space with isotropic scattering the whole reflection is known exactly
(Chandrasekhar 1960, *Radiative Transfer*, eq. IV.(29); :func:`.incidence.index_matched_brdf`):

.. math:: f(\mu_0, \mu) = \frac{\omega}{4\pi}\,\frac{H(\mu_0)\,H(\mu)}{\mu_0 + \mu},

of which the first bounce is :math:`\omega/(4\pi(\mu_0 + \mu))`. Its exit lobe is not flat: at
albedo 0.72 (ketchup's red) the radiance toward the normal is 11 % below the flat lobe's and
18 % above it near grazing; at albedo 0.998 (marble) the other way round, 3 % above and 8 %
below. The transport tables' own exit cones (an independent random walk with Fresnel
boundaries, normal incidence) follow this shape to 0.5 % at eta 1, where the flat lobe is
3-15 % off them.

This module gives the lobe per unit exitance of that kernel,

.. math:: \Lambda(\mu \mid \mu_0) = \frac{F_t(\mu, \eta)\,S(\mu_i, \mu_0)}
          {\int_0^1 2\pi\mu'\,F_t(\mu', \eta)\,S(\mu'_i, \mu_0)\,d\mu'},\qquad
          S(\mu_i, \mu_0) = \frac{H(\mu_0)H(\mu_i) - s}{\mu_0 + \mu_i},

with :math:`\mu_i` the exit cosine refracted inside (Snell), :math:`\mu_0` the incidence
cosine inside, and :math:`s = 1` when the first bounce is rendered apart (the renderer's
single-scattering pass replaces its share: the lobe is then the multiple scattering's), else 0.
It integrates to 1 against :math:`\cos\theta\,d\omega` for every :math:`\mu_0`, so it moves
light between angles and changes no total. At eta 1 it is exact for isotropic scattering in the
similarity albedo :math:`\sigma_s'/\sigma_t'`; behind a Fresnel boundary (eta 1.3 and 1.5) the
same kernel at the refracted cosines, times the boundary's transmittance, is within 1.0-1.7 %
of the tables' exit cones where the flat lobe is 0.6-7 % off (the boundary's internal
reflections make the light a little more diffuse than this; ``tests/jsss/test_exit_law.py``).

Light arrives at a point from several lights at once, and the exitance there is a blur of its
neighbourhood's. The lobe is the mix of the kernels of the lights at the point, each weighted
by the flux it sends in (:meth:`ExitLaw.weights`), on 17 incidence nodes
:math:`\mu_0 = 0, 1/16, \dots, 1` (linear between them: within 0.55 % of the kernel at any
incidence); an environment and the light that reaches a point only through the blur (its
shadow, the far side) take the kernel of uniform illumination, which by reciprocity is
:math:`\propto F_t(\mu) A(\mu_i)`, the plane albedo at the exit angle (the oblique-incidence
law's, so that a non-absorbing object in a white furnace stays invisible behind any eta).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..fresnel import (
    diffuse_fresnel_transmittance,
    fresnel_transmittance,
    refracted_cosine,
)
from ..medium import Medium
from ..numerics import as_float_array
from .incidence import _nodes, h_function, h_function_numpy, largest_albedo

__all__ = ["ExitLaw", "exit_law", "lobe_change"]

INCIDENCE_NODES = 17         # mu0 = 0, 1/16, ..., 1 (inside): the kernel is linear between them (0.55 % at worst)
GRAZING = 1.0 / 64           # the first node's kernel is evaluated here: at mu0 = mu = 0 it is 1/0
QUADRATURE = 96              # Gauss-Legendre nodes of each normalising integral over the exit cosine
LAST_LEG_SMALLEST_COSINE = 1e-6  # last_leg_depth's inside cosine is held above 0 (uniform light's slope is log 1/mu)
UNLIT_SHARE = 1e-3           # of the frame's brightest point's flux: below it a point's lobe leans to uniform light


class ExitLaw(eqx.Module):
    """Chandrasekhar's exit lobe of one medium (module docstring): build with :func:`exit_law`.

    A pytree of arrays with channels ``C`` leading nothing (shapes below); jit, vmap and grad
    go through it like any medium.

    Attributes
    ----------
    eta : (C,) relative index
    root, half : (C,) :math:`\\sqrt{1 - \\omega}` and :math:`\\omega/2`, the H equation's terms
    node_mu : (J,) Gauss-Legendre nodes on [0, 1]; node_terms : (C, J) :math:`w_j\\mu_j H(\\mu_j)`
    h_incident : (C, K) :math:`H` at the incidence nodes
    norm : (C, K + 1) the normalising integral of each node's kernel, the last uniform light's
    uniform : (C, K + 1) the weights of uniform light: 1 on the last, uniform-light column
    first_bounce : 1.0 when the first bounce is rendered apart (its kernel removed), else 0.0
    """

    eta: jax.Array
    root: jax.Array
    half: jax.Array
    node_mu: jax.Array
    node_terms: jax.Array
    h_incident: jax.Array
    norm: jax.Array
    uniform: jax.Array
    first_bounce: float = eqx.field(static=True)

    def _sums(self, mu):
        """The H equation's sum :math:`\\sum_j w_j\\mu_j H(\\mu_j)/(\\mu + \\mu_j)`, shape of ``mu``:
        :math:`H(\\mu) = 1/(\\sqrt{1 - \\omega} + (\\omega/2)\\,\\mathrm{sums})` (Nystrom, no table)."""
        return (self.node_terms / (mu[..., None] + self.node_mu)).sum(-1)

    def kernel(self, cos_exit):
        """:math:`F_t(\\mu)\\,S(\\mu_i, \\mu_{0,k})` at outside exit cosine ``cos_exit`` (shape ``S``),
        and last uniform light's :math:`F_t(\\mu) A(\\mu_i)`: shape ``S + (C, K + 1)``, unnormalised."""
        mu = jnp.clip(as_float_array(cos_exit), 0.0, 1.0)[..., None]            # S + (1,)
        inside = refracted_cosine(mu, self.eta)                                 # S + (C,)
        return fresnel_transmittance(mu, self.eta)[..., None] * self._inside_kernel(inside)

    def _inside_kernel(self, inside):
        """:math:`S(\\mu_i, \\mu_{0,k})` and uniform light's :math:`A(\\mu_i)` at the inside exit
        cosine ``inside`` (shape ``S + (C,)``): shape ``S + (C, K + 1)``, no boundary."""
        sums = self._sums(inside)
        h_exit = 1.0 / (self.root + self.half * sums)
        incident = _incidence_mu(inside.dtype)                                  # (K,)
        s = (self.h_incident * h_exit[..., None] - self.first_bounce) / (incident + inside[..., None])
        # Uniform light: by reciprocity the plane albedo at the exit angle, A = 1 - H sqrt(1 - w),
        # less the first bounce's (w/2)(1 - mu ln(1 + 1/mu)) when apart, both over w/2. Written
        # without 1 - H's cancellation (H - 1 = (w/2) H (2/(1 + root) - sums)), which had left
        # float32 nothing at albedo 1e-4: A/(w/2) = 2/(1 + root) - root H (2/(1 + root) - sums).
        positive = inside > 0
        log_term = jnp.where(positive, inside * jnp.log1p(1 / jnp.where(positive, inside, 1.0)), 0.0)
        lead = 2 / (1 + self.root)
        uniform = lead - self.root * h_exit * (lead - sums) - self.first_bounce * (1 - log_term)
        return jnp.concatenate([s, uniform[..., None]], -1)

    def weights(self, cos_incident, flux):
        """Node weights (shape ``S + (C, K + 1)``, the last, uniform light's, 0) of light entering
        at outside cosine ``cos_incident`` (shape ``S``) with ``flux`` (shape ``S + (C,)``, irradiance before the boundary): the
        flux times the boundary's transmittance, split linearly over the two nearest incidence
        nodes of the refracted cosine. Sum it over lights for :meth:`lobe`."""
        mu = jnp.clip(as_float_array(cos_incident), 0.0, 1.0)[..., None]
        inside = refracted_cosine(mu, self.eta)                                 # S + (C,)
        entering = flux * fresnel_transmittance(mu, self.eta)
        position = inside[..., None] * (INCIDENCE_NODES - 1) - jnp.arange(INCIDENCE_NODES + 1, dtype=inside.dtype)
        hats = jnp.maximum(1 - jnp.abs(position), 0.0) * (jnp.arange(INCIDENCE_NODES + 1) < INCIDENCE_NODES)
        return entering[..., None] * hats                                       # the uniform column 0

    def lobe(self, cos_exit, weights=None):
        """Radiance per unit exitance toward outside cosine ``cos_exit`` (shape ``S``) [1/sr],
        shape ``S + (C,)``, for light that arrived with node ``weights`` (``S + (C, K + 1)``, from
        :meth:`weights`; None: uniform illumination).

        Where a point's weights are small against the frame's largest (shadowed points, lit
        only through the blur) the uniform kernel takes over smoothly: a point is given
        ``UNLIT_SHARE`` of the brightest point's flux as uniform light."""
        kernel = self.kernel(cos_exit)
        weights = self._mixed(weights, kernel.shape)
        total = (weights * self.norm).sum(-1)
        # A medium that returns no multiply scattered light (albedo 0) has no kernel: the flat lobe.
        flat = fresnel_transmittance(jnp.clip(as_float_array(cos_exit), 0.0, 1.0)[..., None], self.eta) \
            / (jnp.pi * diffuse_fresnel_transmittance(self.eta))
        ok = total > 0
        return jnp.where(ok, (weights * kernel).sum(-1) / jnp.where(ok, total, 1.0), flat)

    def _mixed(self, weights, shape):
        """The node weights a point's lobe is mixed with (:meth:`lobe`): uniform light's where
        ``weights`` is None, else ``weights`` plus ``UNLIT_SHARE`` of the frame's brightest
        point's flux as uniform light."""
        if weights is None:
            return jnp.broadcast_to(self.uniform, shape)
        per_point = weights.sum(-1)                                              # S + (C,)
        # (not held under differentiation: the lobe stays of degree 0 in the light's intensity)
        scale = per_point.reshape(-1, per_point.shape[-1]).max(0)
        scale = jnp.where(scale > 0, scale, 1.0)
        return weights + UNLIT_SHARE * scale[..., None] * self.uniform

    def last_leg_depth(self, cos_exit, weights=None):
        r"""Mean optical depth :math:`\langle\tau\rangle` (in :math:`1/\sigma_t'`) at which the light
        leaving toward outside cosine ``cos_exit`` (shape ``S``) was last scattered, and the
        inside cosine :math:`\mu` of its last leg: two arrays of shape ``S + (C,)``.

        For light that arrived with node ``weights`` (as :meth:`lobe`: a mix of the nodes'
        kernels, so of their Laplace transforms; :mod:`jsss.diffusion.lateral_step` derives it):

        .. math:: \langle\tau\rangle = \mu + \mu^2\,
                  \frac{\sum_k w_k\,\partial_\mu S_k(\mu)}{\sum_k w_k\,S_k(\mu)}.

        The boundary's transmittance scales the light that leaves, not where it was scattered:
        it does not enter. At one incidence node this is
        :func:`jsss.diffusion.lateral_step.last_leg_step`'s depth (tested)."""
        kernel, slope, inside = self.last_leg_table(cos_exit)
        return self.mixed_depth(inside, kernel, slope, weights), inside

    def last_leg_table(self, cos_exit):
        """What :meth:`last_leg_depth` mixes, at outside cosines ``cos_exit`` (shape ``S``): the
        kernels :math:`S_k(\\mu)` and their slopes :math:`\\partial_\\mu S_k` (shape ``S + (C, K + 1)``)
        and the inside cosine :math:`\\mu` (shape ``S + (C,)``), held above 0."""
        mu = jnp.clip(as_float_array(cos_exit), 0.0, 1.0)[..., None]
        inside = jnp.maximum(refracted_cosine(mu, self.eta), LAST_LEG_SMALLEST_COSINE)    # S + (C,)
        kernel, slope = jax.jvp(self._inside_kernel, (inside,), (jnp.ones_like(inside),))
        return kernel, slope, inside

    def mixed_depth(self, inside, kernel, slope, weights=None):
        """:math:`\\langle\\tau\\rangle` of :meth:`last_leg_depth` from :meth:`last_leg_table`'s parts."""
        weights = self._mixed(weights, kernel.shape)
        total = (weights * kernel).sum(-1)
        ok = total > 0   # albedo 0 with the first bounce apart returns nothing to place
        ratio = jnp.where(ok, (weights * slope).sum(-1) / jnp.where(ok, total, 1.0), 0.0)
        return inside + inside**2 * ratio


def _incidence_mu(dtype):
    """The incidence nodes (K,) inside, the grazing one moved to ``GRAZING``."""
    mu = np.linspace(0.0, 1.0, INCIDENCE_NODES)
    mu[0] = GRAZING
    return jnp.asarray(mu, dtype)


def exit_law(medium: Medium, *, first_bounce_apart: bool) -> ExitLaw:
    r"""The exit law of ``medium`` (channels ``C``): solves H once, here (per channel).

    ``first_bounce_apart``: the frame renders single scattering by its own pass (the lobe is
    then that of the second and later bounces). Uses the similarity albedo
    :math:`\sigma_s'/(\sigma_a + \sigma_s')`, in the medium's dtype.
    """
    albedo = medium.sigma_s_prime / (medium.sigma_a + medium.sigma_s_prime)
    albedo = jnp.atleast_1d(albedo)
    eta = jnp.broadcast_to(jnp.asarray(medium.eta, albedo.dtype), albedo.shape)
    dtype = albedo.dtype
    node_mu, node_w = _nodes(dtype)
    capped = largest_albedo(albedo, dtype)                   # as h_function: no fixed scale at 1
    h_nodes = h_function(capped, node_mu).T                  # (C, J)
    incident = _incidence_mu(dtype)
    law = ExitLaw(eta=eta, root=jnp.sqrt(jnp.maximum(1 - capped, 0.0)), half=capped / 2, node_mu=node_mu,
                  node_terms=node_w * node_mu * h_nodes, h_incident=h_function(capped, incident).T,
                  norm=jnp.ones(albedo.shape + (INCIDENCE_NODES + 1,), dtype),
                  uniform=jnp.broadcast_to(jnp.arange(INCIDENCE_NODES + 1) == INCIDENCE_NODES,
                                           albedo.shape + (INCIDENCE_NODES + 1,)).astype(dtype),
                  first_bounce=1.0 if first_bounce_apart else 0.0)
    # The normalising integrals over the outside exit cosine (Gauss-Legendre in mu^2: the
    # integrand carries mu d mu).
    x, w = np.polynomial.legendre.leggauss(QUADRATURE)
    mu = jnp.asarray(np.sqrt((x + 1) / 2), dtype)            # mu^2 uniform on [0, 1]
    dmu2 = jnp.asarray(w / 2, dtype)                          # weights of d(mu^2) = 2 mu d mu
    norm = jnp.pi * jnp.einsum("q,qck->ck", dmu2, law.kernel(mu))
    return eqx.tree_at(lambda e: e.norm, law, norm)


VIEW_COSINES = (1.0, 0.5, 0.2)   # where the planner weighs the lobe: along the normal, at 60 and at 78 degrees


def lobe_change(medium: Medium, *, first_bounce_apart: bool, cosines=VIEW_COSINES) -> np.ndarray:
    r"""How far Chandrasekhar's lobe is from the flat diffusion lobe (:func:`jsss.fresnel.exit_lobe`):
    per channel (shape ``C``, signed), the largest relative change of the radiance toward any of
    ``cosines`` (outside), under a normal beam and under uniform light. In NumPy, for the
    planner (concrete media only): the same kernel and normalisation as :class:`ExitLaw`,
    without its incidence nodes."""
    sigma_a, sigma_s_prime = np.asarray(medium.sigma_a, float), np.asarray(medium.sigma_s_prime, float)
    albedo = np.atleast_1d(sigma_s_prime / (sigma_a + sigma_s_prime))
    eta = np.broadcast_to(np.asarray(medium.eta, float), albedo.shape)
    x, w = np.polynomial.legendre.leggauss(QUADRATURE)
    quad, dmu2 = np.sqrt((x + 1) / 2), w / 2                  # as exit_law: d(mu^2) on [0, 1]
    views = np.asarray(cosines, float)
    inside = lambda mu: np.sqrt(np.maximum(1 - (1 - mu[:, None] ** 2) / eta**2, 0.0))   # (S, C)
    view_in, quad_in = inside(views), inside(quad)
    h = h_function_numpy(albedo, np.concatenate([view_in, quad_in, np.ones((1,) + albedo.shape)]))
    h_view, h_quad, h_normal = h[:len(views)], h[len(views):-1], np.diagonal(h[-1])
    h_view, h_quad = (np.diagonal(a, axis1=1, axis2=2) for a in (h_view, h_quad))   # H of each channel's own cosine
    s = 1.0 if first_bounce_apart else 0.0
    entering = dmu2[:, None] * _transmittance_numpy(quad, eta)                        # (Q, C)

    root = np.sqrt(np.maximum(1 - albedo, 0.0))

    def beam(h_exit, mu_exit):      # a normal beam's kernel
        return (h_normal * h_exit - s) / (1 + mu_exit)

    def uniform(h_exit, mu_exit):   # uniform light's: the plane albedo at the exit angle (ExitLaw.kernel)
        return 1 - root * h_exit - s * albedo / 2 * (1 - mu_exit * np.log1p(1 / np.maximum(mu_exit, 1e-300)))

    ratios = []
    for kernel in (beam, uniform):
        # lobe / flat lobe = K(view) T_dr / sum_q dmu2 F_t K(q), with T_dr = sum_q dmu2 F_t
        ratios.append(kernel(h_view, view_in) * entering.sum(0) / (entering * kernel(h_quad, quad_in)).sum(0))
    changes = np.concatenate(ratios) - 1
    return changes[np.argmax(np.abs(changes), 0), np.arange(albedo.size)]


def _transmittance_numpy(cos, eta) -> np.ndarray:
    """Unpolarised Fresnel transmittance entering ``eta`` (C,) at outside cosines ``cos`` (Q,): (Q, C),
    :func:`jsss.fresnel.fresnel_transmittance` in NumPy (for :func:`lobe_change`)."""
    cos = np.asarray(cos, float)[:, None]
    cos_t = np.sqrt(np.maximum(1 - (1 - cos**2) / eta**2, 0.0))
    rs = (cos - eta * cos_t) / np.maximum(cos + eta * cos_t, 1e-300)
    rp = (eta * cos - cos_t) / np.maximum(eta * cos + cos_t, 1e-300)
    return 1 - 0.5 * (rs**2 + rp**2)
