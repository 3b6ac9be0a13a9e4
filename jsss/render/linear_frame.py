r"""The texture-space frame as a function linear in the profile's weights and the albedo.

With the Gaussian variances :math:`v_i` of the render profile held fixed, texture-space
diffusion (d'Eon, Luebke, Enderton 2007 sec. 5) is linear in the weights :math:`w_{ic}`: each
variance's blurred irradiance texture is computed once and the exitance is their weighted
sum (the translucent shadow maps' light, sec. 5.4, is a weighted sum of the same textures).
Jensen's single-scattering term (Jensen et al. 2001 sec. 2.2; Henyey-Greenstein with
:math:`g = 0` on the reduced coefficients) is the albedo :math:`\alpha' = \sigma_s'/\sigma_t'`
times a factor of the geometry and :math:`\eta` alone. So the frame of
:func:`jsss.render.render` is, per pixel :math:`x` and channel :math:`c`,

.. math:: L_c(x) = c(x)\,\Bigl(\max\bigl(\textstyle\sum_i w_{ic} B_{ic}(x)
          - \alpha'_c M^{(1)}_c(x),\, 0\bigr)\,\Lambda_c(x) + \alpha'_c L^{(1)}_c(x) + S_c(x)\Bigr)

with, all fixed for a scene and plan (:class:`LinearFrame`):

* :math:`B_{ic}` [W/mm^2 per unit weight] -- the pixel's diffusion exitance of Gaussian
  :math:`i` with unit weight: :math:`(G(v_i) * E)` looked up at the pixel, plus its
  translucent-shadow-map light when that pass runs;
* :math:`\Lambda_c` [1/sr] -- the exit lobe :math:`F_t(\cos\theta_o, \eta)/(\pi(1 - F_{dr,ext}))`,
  or with the exit-angle pass Chandrasekhar's lobe of the light arriving at the pixel
  (:mod:`jsss.diffusion.exit_law`);
* :math:`L^{(1)}_c` [W/(mm^2 sr)], :math:`M^{(1)}_c` [W/mm^2] -- single-scattered radiance and
  exitance at albedo 1 (when the plan runs that pass);
* :math:`S_c` [W/(mm^2 sr)] -- the specular lobe (when the plan runs it);
* :math:`c` -- the share of the pixel the surface covers.

The parts come from the same code as the frame of :func:`jsss.render.render` -- the textures
from the stages of :class:`jsss.render.methods.TextureSpace`, the per-pixel parts from
:func:`jsss.render.methods.camera_parts` -- and are put together by the same
:func:`jsss.render.shading.frame_radiance`: at the plan's own material
:meth:`LinearFrame.radiance` is that frame up to rounding (tested). Away from it, what
depends on the medium besides the weights and the albedo is held at the plan's: the
legs' steps and the first bounce's share of their move (:mod:`jsss.render.last_leg`,
:mod:`jsss.render.first_leg`); a fit (:func:`fitting.render.fit_render`) re-plans when those
move. The irradiance's oblique-incidence law and the depth at which point lights are read
(:mod:`jsss.diffusion.incidence`) follow the medium given to :meth:`LinearFrame.radiance`, read at
the pixel: the diffusion light is scaled by :math:`\rho(x) = \sum_l E_l(x) f_l(x; m) / \sum_l E_l(x)
f_l(x; m_0)`, each light's transmitted irradiance :math:`E_l` at the pixel times its laws at the
medium :math:`m` over those at the plan's :math:`m_0`. Exact where the laws' factor is uniform
over the profile's reach (a directional light on a plane; tested to 1e-10); where it varies (a
point light's foot) the error is that variation across the profile. Against render() of the
moved medium on the same plan (legs held on both sides): the ketchup plane at 160 x 120 from
its medium to a fit's (red mean free path 4.1 -> 6.4 mm), relative RMS per pixel 1.9 % held,
0.08 % followed; to 11.8 mm, 6.9 % and 0.49 %; marble with sigma_a x 1.5 and sigma_s' x 0.7,
0.41 % and 0.13 %. An environment's share, single scattering's deposit depth, and every law
under translucent shadow maps (their light entered on the far side) stay held. The exit law
(:mod:`jsss.diffusion.exit_law`) depends on the albedo alone and follows it:
:meth:`LinearFrame.radiance` recomputes the lobe from it.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..diffusion.exit_law import exit_law
from ..diffusion.incidence import deposit_depth, incidence_law
from ..medium import Medium
from .environment import EnvironmentGeometry
from .last_leg import moved_ratio
from .lighting import depth_falloff, irradiance
from .methods import TextureSpace, camera_parts
from .passes import Pass
from .planner import Plan
from .renderer import render_params
from .scene import Scene
from .shading import exit_weights, frame_radiance

__all__ = ["LinearFrame", "linear_frame"]


class LinearFrame(eqx.Module):
    """The fixed parts of a texture-space frame (module docstring); arrays in one dtype.

    Attributes
    ----------
    basis : (n, H, W, C) [W/mm^2], each Gaussian's pixel exitance with unit weight, :math:`B_i`
    variances : (n,) [mm^2], the Gaussians' variances
    exit_lobe : (H, W, C) [1/sr], radiance per unit diffusion exitance toward the camera
    coverage : (H, W), share of each pixel the surface covers
    single_radiance, single_exitance : (H, W, C) or None, single scattering at albedo 1
        [W/(mm^2 sr)] and [W/mm^2]; None when the plan does not run that pass
    specular : (H, W, C) or None [W/(mm^2 sr)], the surface reflection; None when off
    exit_weights : (H, W, C, K) or None, with the exit-angle pass the incidence-node weights of
        the light at each pixel (:func:`jsss.render.shading.exit_weights`): the lobe is then
        Chandrasekhar's at the albedo :meth:`radiance` is given, and :attr:`exit_lobe` the
        plan's own; None when off
    cos_view : (H, W) or None, the exit cosine toward the camera (with ``exit_weights``)
    eta : (C,) or None, the relative index (with ``exit_weights``)
    first_bounce_apart : whether single scattering runs apart (the exit law's kernel without it)
    law_light : (L, H, W, C) or None [W/mm^2], each point or directional light's transmitted
        irradiance at the pixel without the laws; None when the plan runs neither law
    law_cosine, law_distance : (L, H, W) or None, each light's incidence cosine and distance [mm]
        (infinite for a directional light) at the pixel
    law_held : (H, W, C) or None [W/mm^2], the pixel's transmitted irradiance with the laws at
        the plan's medium, every light's and an environment's (the ratio's denominator)
    law_rest : (H, W, C) or None [W/mm^2], an environment's share (its laws held)
    oblique, deposit : whether the plan runs the oblique-incidence law and the deposit depth
    """

    basis: jax.Array
    variances: jax.Array
    exit_lobe: jax.Array
    coverage: jax.Array
    single_radiance: jax.Array | None = None
    single_exitance: jax.Array | None = None
    specular: jax.Array | None = None
    exit_weights: jax.Array | None = None
    cos_view: jax.Array | None = None
    eta: jax.Array | None = None
    first_bounce_apart: bool = eqx.field(static=True, default=False)
    law_light: jax.Array | None = None
    law_cosine: jax.Array | None = None
    law_distance: jax.Array | None = None
    law_held: jax.Array | None = None
    law_rest: jax.Array | None = None
    oblique: bool = eqx.field(static=True, default=False)
    deposit: bool = eqx.field(static=True, default=False)

    def law_ratio(self, medium: Medium):
        r"""(H, W, C): the diffusion light's factor at ``medium`` over the plan's, from the
        irradiance's laws read at each pixel (module docstring); 1 without them."""
        if self.law_light is None:
            return jnp.ones(self.exit_lobe.shape, self.basis.dtype)
        factor = jnp.ones(self.law_light.shape, self.basis.dtype)
        if self.oblique:
            factor = factor * incidence_law(medium)(self.law_cosine)
        if self.deposit:  # every light at once: (L, H, W) geometry, (C,) depth
            geometry = _Geometry(self.law_cosine, self.law_distance)
            factor = factor * depth_falloff(geometry, deposit_depth(medium), self.basis.dtype)
        now = (self.law_light * factor).sum(0) + self.law_rest
        lit = self.law_held > 0
        return jnp.where(lit, now / jnp.where(lit, self.law_held, 1.0), 1.0)  # double where: unlit pixels stay 1

    def radiance(self, weights, albedo=None, medium=None):
        r"""Linear radiance (H, W, C) for Gaussian ``weights`` (n, C) on :attr:`variances` and the
        reduced albedo ``albedo`` (C,) :math:`\sigma_s'/\sigma_t'` (read only when the frame has
        single scattering or the exit-angle pass, whose lobe it sets). Linear in ``weights``;
        differentiable in all. ``medium``: the medium whose oblique-incidence law and deposit
        depth the diffusion light follows (:meth:`law_ratio`); None holds the plan's."""
        exitance = jnp.einsum("nc,nhwc->hwc", weights.astype(self.basis.dtype), self.basis)
        if medium is not None and self.law_light is not None:
            exitance = exitance * self.law_ratio(medium)
        if albedo is None and (self.single_radiance is not None or self.exit_weights is not None):
            raise ValueError("LinearFrame.radiance: this frame has single scattering or the exit-angle pass; pass "
                             "albedo= (sigma_s' / (sigma_a + sigma_s') per channel).")
        single = None
        if self.single_radiance is not None:
            single = (albedo * self.single_radiance, albedo * self.single_exitance)
        lobe = self.exit_lobe
        if self.exit_weights is not None:  # the exit law of a medium of this similarity albedo
            albedo = jnp.asarray(albedo, self.basis.dtype)
            law = exit_law(Medium(1 - albedo, albedo, self.eta), first_bounce_apart=self.first_bounce_apart)
            lobe = law.lobe(self.cos_view, self.exit_weights)
        return frame_radiance(exitance, lobe, self.coverage, single_scattering=single, specular=self.specular)


def linear_frame(scene: Scene, plan: Plan, *, dtype=jnp.float64, blur_dtype=None, prepared=None) -> LinearFrame:
    """The fixed parts of ``scene``'s texture-space frame under ``plan`` (module docstring).

    Parameters
    ----------
    scene : Scene
    plan : Plan
        A texture-space plan (``plan.method_config`` a :class:`~jsss.render.methods.TextureSpace`).
    dtype : the arrays' dtype
    blur_dtype : optional
        Dtype of the irradiance and its blur, the one costly pass (default ``dtype``). A fit
        may take float32 there: its images are then good to about 1e-7, far below a photo's
        noise, at half the time.
    prepared : TexturePrepared, optional
        The plan's prepared geometry, if it is at hand (``render(...).prepared``).

    Raises
    ------
    ValueError
        The plan's method is not texture space (other methods are not linear in the weights), or
        the material has parameter maps.
    """
    method = plan.method_config
    if not isinstance(method, TextureSpace):
        raise ValueError(f"linear_frame: the frame is linear in the profile's weights for texture space only; the "
                         f"plan's method is {plan.method} (plan_scene(..., method='texture-space')).")
    maps = scene.material.maps
    if maps is not None and maps.parametric:
        raise ValueError(f"linear_frame: {scene.source}'s material has parameter maps, whose frame is a blend of "
                         "basis profiles, not one profile's weights; a colour map (albedo) is linear and allowed.")
    blur_dtype = dtype if blur_dtype is None else blur_dtype
    prepared = method.prepare(scene, plan) if prepared is None else prepared
    params = render_params(scene, plan, dtype=dtype)
    low = render_params(scene, plan, dtype=blur_dtype)
    blurred = method.diffusion(low, prepared, method.irradiance(low, prepared))
    textures = []
    for i in range(len(plan.variances)):  # exitance is linear in the weights: one image per variance, unit weight
        term = eqx.tree_at(lambda p: (p.weights, p.variances), low,
                           (jnp.ones((1, 3), blur_dtype), low.variances[i:i + 1]))
        textures.append(method.texel_exitance(term, prepared, blurred[i:i + 1]))
    textures = jnp.stack(textures)
    # With the pass "last leg" each channel is read where its light was last scattered, the step
    # held at the plan's medium (as the irradiance's laws are); one step for every image.
    images = method.pixel_exitance(low, prepared, textures).astype(dtype)
    unit = None  # single scattering at albedo 1: the geometry's factor alone
    if params.medium is not None:
        unit = Medium(jnp.zeros(3, dtype), jnp.ones(3, dtype), params.eta)
    lobe, single, specular = camera_parts(params, prepared.shading, dtype, medium=unit)
    single_radiance, single_exitance = (None, None) if single is None else single
    if single is not None and method.moves_light(low, prepared):
        # The first bounce moves with the exitance, by the ratio at the plan's weights (held, as the step)
        weights = params.weights.astype(dtype)
        at_pixels = method.pixel_lookup(prepared, textures).astype(dtype)
        ratio = moved_ratio(jnp.einsum("nc,nhwc->hwc", weights, images),
                            jnp.einsum("nc,nhwc->hwc", weights, at_pixels))
        single_radiance, single_exitance = single_radiance * ratio, single_exitance * ratio
    exit_parts = {}
    if params.exit_angle is not None:
        shading = prepared.shading
        law = exit_law(params.exit_angle, first_bounce_apart=single is not None)   # its weights need eta alone
        exit_parts = {
            "exit_weights": exit_weights(law, [g.astype(dtype) for g in shading.lights], params.radiant, params.eta),
            "cos_view": jnp.asarray((shading.normal * shading.view).sum(-1), dtype), "eta": params.eta,
            "first_bounce_apart": single is not None}
    # The laws follow the medium at the pixel, from the pixel's own lights; not with translucent
    # shadow maps, whose light entered on the far side (on a thin fin lit from behind, read at
    # the front they moved the frame further from the medium's own than holding them did).
    follow = (params.oblique or params.deposit) and not plan.on(Pass.TRANSLUCENT_SHADOW_MAPS)
    law_parts = _law_parts(params, prepared.shading.lights, dtype) if follow else {}
    return LinearFrame(images, jnp.asarray(plan.variances, dtype), lobe,
                       jnp.asarray(prepared.shading.coverage, dtype), single_radiance, single_exitance, specular,
                       **exit_parts, **law_parts)


class _Geometry(NamedTuple):
    """What :func:`jsss.render.lighting.depth_falloff` reads of a light's geometry."""
    cosine: jax.Array
    distance: jax.Array


def _law_parts(params, lights, dtype) -> dict:
    """:class:`LinearFrame`'s ``law_*`` fields: each point or directional light at the pixels, its
    irradiance without the laws, and the pixel's irradiance with them at the plan's medium."""
    radiant = params.radiant.astype(dtype)
    rest = jnp.zeros(tuple(np.shape(lights[0].cosine)) + (radiant.shape[-1],), dtype)
    light, cosine, distance = [], [], []
    held = jnp.zeros_like(rest)  # every light's with the plan's laws
    for i, g in enumerate(lights):
        if isinstance(g, EnvironmentGeometry):
            rest = rest + irradiance([g], radiant[i:i + 1], params.eta, medium=params.oblique)
            continue
        g = g.astype(dtype)
        light.append(irradiance([g], radiant[i:i + 1], params.eta))
        held = held + irradiance([g], radiant[i:i + 1], params.eta, medium=params.oblique, deposit=params.deposit)
        cosine.append(jnp.clip(g.cosine, 0.0, 1.0))
        distance.append(jnp.broadcast_to(jnp.asarray(g.distance, dtype), g.cosine.shape))
    if not light:
        return {}
    return {"law_light": jnp.stack(light), "law_cosine": jnp.stack(cosine), "law_distance": jnp.stack(distance),
            "law_held": held + rest, "law_rest": rest, "oblique": params.oblique is not None,
            "deposit": params.deposit is not None}

