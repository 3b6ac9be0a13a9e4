r"""Texture-space diffusion (d'Eon, Luebke, Enderton 2007 sec. 5): the irradiance blurred on the surface.

The irradiance is rendered into the mesh's UV layout, blurred once per Gaussian of the
profile's sum-of-Gaussians fit by a chain of separable, stretch-corrected blurs (each from
the one before, :mod:`jsss.render.blur`), and the exitance is their weighted sum

.. math:: M(x) = \sum_i w_i\,(G(v_i) * E)(x)
          \;+\; \sum_i w_i\,e^{-d^2/2v_i}\,(G(v_i) * E)(x_{front})

[W/mm^2], the second term the translucent shadow maps' light through thin parts (d'Eon
sec. 5.4, :func:`jsss.render.lighting.translucent_transmission`). The camera looks it up at
each pixel and spreads it by the exit lobe (:func:`~jsss.render.methods.base.camera_radiance`).
With the variances fixed the frame is linear in the weights: :mod:`jsss.render.linear_frame`
keeps each Gaussian's image apart for a fit.
"""

from __future__ import annotations

import numbers
import time
from dataclasses import dataclass
from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..blur import blur_schedule, hierarchical_blur, uniform_stretch
from ..first_leg import FIRST_LEG_QUANTILE_COUNT, first_leg_moves, first_leg_quantiles
from ..last_leg import (
    last_leg_steps,
    moved_lookup,
    moved_ratio,
    uv_jacobians,
    uv_per_mm_away_from_eye,
)
from ..lighting import lookup, translucent_transmission
from ..memory import camera_key, kept, mesh_key
from ..mesh import is_closed
from ..passes import Method, Pass
from ..raster import surface_attributes
from ..surface_maps import MapSampler, crossing_light, read_points, scaled
from ..texture_space import TexelGeometry, bake_texels
from .base import (
    PixelShading,
    PreparedGeometry,
    RenderMethod,
    camera_radiance,
    entry_irradiance,
    kept_camera,
    kept_lights,
    kept_shadow_maps,
    pixel_shading,
)

__all__ = ["TexturePrepared", "TextureSpace"]

FIRST_LEG_QUANTILES = tuple(float(q) for q in first_leg_quantiles(FIRST_LEG_QUANTILE_COUNT))


@dataclass(frozen=True, eq=False)
class TexturePrepared(PreparedGeometry):
    """Geometry-only data of a scene under a texture-space plan (NumPy arrays).

    Attributes
    ----------
    texels : TexelGeometry; texel_lights : tuple of LightGeometry per light at the texels
    pixel_mask : (H, W) bool; pixel_uv : (H, W, 2) where each pixel looks up the texture
    shading : PixelShading, the camera pass's data
    stretch : (S, S, 2), a (2,) pair or a (u, v) tuple of scalars and maps: world length of a texel step
    schedule : BlurSchedule, or None when the plan turns diffusion off
    translucent_shadow_maps : bool, whether the plan runs that pass
    open_margin : int, unlit texels padded around the texture of an open surface (see :meth:`TextureSpace.diffusion`)
    colour_map, coefficient_map : MapSampler or None, where each texel reads the material's colour
        map (bilinearly) and parameter maps (the map texel it falls in) (:mod:`jsss.render.surface_maps`)
    uv_per_mm : (H, W, 2) or None, how far each pixel's UV moves per mm away from the eye, when the
        plan runs the pass "last leg" (:mod:`jsss.render.last_leg`)
    uv_jacobian : (H, W, 2, 3) or None, how far each pixel's UV moves per mm along any tangent,
        when the plan runs the pass "first leg" (:mod:`jsss.render.first_leg`)
    margin_kept : bool, whether the blurred textures keep the open surface's margin, so that a
        pixel near the rim whose light moved past it reads the light carried off there (the legs'
        passes on an open surface without parameter maps or translucency; a colour map's exit
        layer is the rim's there)
    """

    texels: TexelGeometry
    texel_lights: tuple
    pixel_mask: np.ndarray
    pixel_uv: np.ndarray
    shading: PixelShading
    stretch: np.ndarray | tuple
    schedule: object
    translucent_shadow_maps: bool = False
    open_margin: int = 0
    colour_map: MapSampler | None = None
    coefficient_map: MapSampler | None = None
    uv_per_mm: np.ndarray | None = None
    uv_jacobian: np.ndarray | None = None
    margin_kept: bool = False

    def texture_reading(self):
        """``(scale, offset, mask)``: a texel UV ``uv`` is ``uv * scale + offset`` in the textures
        the stages carry (with the margin kept, the padded ones) and ``mask`` their valid texels."""
        mask, m = self.texels.mask, self.open_margin
        if not self.margin_kept:
            return 1.0, 0.0, mask
        size = mask.shape[0]
        return size / (size + 2 * m), m / (size + 2 * m), jnp.pad(jnp.asarray(mask), m, constant_values=True)


def _stretch(texels: TexelGeometry, correct: bool):
    """World length of a texel step: per texel (stretch correction), or the median texel length
    everywhere; then a scalar per axis whose texels all have one length (a plane's both, a
    sphere's v): the blur reads that axis's taps as slices, not gathers (decided here: in the
    jitted passes the map is traced)."""
    stretch = texels.stretch if correct else np.where(texels.mask[..., None], texels.median_stretch(), 0.0)
    return uniform_stretch(stretch, texels.mask)


@final
class TextureSpace(RenderMethod):
    """d'Eon's texture-space diffusion.

    Attributes
    ----------
    size : int >= 2
        Texels per side of the irradiance texture (the planner takes the smallest power of two
        whose texel is no larger than a pixel's footprint, capped by the scene's).
    taps : odd int >= 3
        Samples of each separable blur pass (d'Eon's 7).
    max_ratio : float > 1
        Each blur step may grow the variance at most this many times (2 below a 15 % target,
        d'Eon's 4 otherwise: on a delta the doubling chain is within 0.2 % of the Gaussian).

    The Gaussians' variances are the plan's (``plan.variances``, the render profile every
    method's parameters are fitted on); :meth:`prepare` builds the blur chain for them.
    """

    method: ClassVar[Method] = Method.TEXTURE_SPACE
    size: int = eqx.field(static=True)
    taps: int = eqx.field(default=7, static=True)
    max_ratio: float = eqx.field(default=4.0, static=True)

    def __check_init__(self):
        if isinstance(self.size, bool) or not isinstance(self.size, numbers.Integral) or self.size < 2:
            raise ValueError(f"TextureSpace(size={self.size!r}): the texture needs a whole number >= 2 of texels per "
                             "side; e.g. TextureSpace(size=512).")
        if isinstance(self.taps, bool) or not isinstance(self.taps, numbers.Integral) or self.taps < 3 \
                or self.taps % 2 == 0:
            raise ValueError(f"TextureSpace(taps={self.taps!r}): a blur pass needs an odd number >= 3 of taps "
                             "(d'Eon's 7); e.g. TextureSpace(size, taps=7).")
        if isinstance(self.max_ratio, bool) or not isinstance(self.max_ratio, numbers.Real) \
                or not 1 < self.max_ratio < np.inf:
            raise ValueError(f"TextureSpace(max_ratio={self.max_ratio!r}): each blur step must grow the variance, by "
                             "a finite factor > 1 (2 or d'Eon's 4); e.g. TextureSpace(size, max_ratio=4.0).")

    def prepare(self, scene, plan, params=None, *, timings: dict | None = None) -> TexturePrepared:
        """Bake texels, shadow maps and the camera's visibility for ``scene``; build the blur chain
        for ``plan.variances``. (``params`` is not read: nothing here depends on the profile.)"""
        timings = {} if timings is None else timings
        mesh_id = mesh_key(scene.mesh)  # each piece is kept while the mesh, camera and lights' positions stay
        t0 = time.perf_counter()
        texels = kept("texels", (mesh_id, self.size), lambda: bake_texels(scene.mesh, self.size))
        timings["texture geometry"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        maps = kept_shadow_maps(scene)
        texel_lights = kept_lights(scene, ("texels", self.size), texels.position, texels.normal, texels.mask, maps)
        timings["shadows"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        camera = kept_camera(scene)  # two-sided: normals turned towards the camera
        at_camera = ("camera", camera_key(scene.camera))
        uv = kept("camera uv", (mesh_id, at_camera),
                  lambda: surface_attributes(camera.raster, scene.mesh.faces, scene.mesh.uvs))
        pixel_lights = kept_lights(scene, at_camera, camera.position, camera.normal, camera.mask, maps)
        timings["camera raster"] = time.perf_counter() - t0
        correct = plan.on(Pass.STRETCH_CORRECTION)
        stretch = kept("texel stretch", (mesh_id, self.size, correct), lambda: _stretch(texels, correct))
        median = kept("median stretch", (mesh_id, self.size), texels.median_stretch)
        schedule = blur_schedule(np.asarray(plan.variances), median, max_ratio=self.max_ratio) \
            if plan.on(Pass.DIFFUSION) else None
        margin = 0
        if schedule is not None and not is_closed(scene.mesh):
            reach = 3.0 * np.sqrt(float(np.max(plan.variances))) / median
            margin = int(min(np.ceil(reach), texels.size // 4))
        colour_map = coefficient_map = None
        maps = scene.material.maps
        if maps is not None and maps.colour is not None:
            colour_map = kept("texel map sampler", (self.size, maps.colour.shape[:2], texels.wrap_u, False),
                              lambda: MapSampler.texels(self.size, maps.colour.shape[:2], wrap_u=texels.wrap_u))
        if maps is not None and maps.parametric:
            # Each map texel is one medium (surface_maps.crossing_light says why)
            coefficient_map = kept("texel map sampler", (self.size, maps.sigma_a.shape[:2], texels.wrap_u, True),
                                   lambda: MapSampler.texels(self.size, maps.sigma_a.shape[:2], wrap_u=texels.wrap_u,
                                                             nearest=True))
        uv_per_mm = uv_jacobian = None
        mesh = scene.mesh
        if plan.on(Pass.LAST_LEG):
            uv_per_mm = kept("camera uv per mm", (mesh_id, at_camera), lambda: uv_per_mm_away_from_eye(
                mesh.vertices, mesh.faces, mesh.uvs, camera.raster, camera.normal, camera.view))
        if plan.on(Pass.FIRST_LEG):
            uv_jacobian = kept("camera uv jacobian", (mesh_id, at_camera),
                               lambda: uv_jacobians(mesh.vertices, mesh.faces, mesh.uvs, camera.raster))
        # Light that moved past an open surface's rim is read from the margin the blur carried it into
        margin_kept = bool(margin and (uv_per_mm is not None or uv_jacobian is not None)
                           and coefficient_map is None and not plan.on(Pass.TRANSLUCENT_SHADOW_MAPS)
                           and not texels.wrap_u)
        return TexturePrepared(texels, texel_lights, camera.mask, uv, pixel_shading(scene, plan, camera, pixel_lights),
                               stretch, schedule, plan.on(Pass.TRANSLUCENT_SHADOW_MAPS), margin, colour_map,
                               coefficient_map, uv_per_mm, uv_jacobian, margin_kept)

    @staticmethod
    def surface(params, prepared: TexturePrepared, dtype):
        """What each texel reads of the maps: ``(entry, exit, coefficients)``
        (:func:`jsss.render.surface_maps.read_points`)."""
        return read_points(params.maps, prepared.colour_map, prepared.coefficient_map, dtype)

    def irradiance(self, params, prepared: TexturePrepared):
        """Light transmitted into the surface at each texel (S, S, C) [W/mm^2]
        (:func:`jsss.render.lighting.irradiance`), through the colour map's layer where there is
        one; with parameter maps, :math:`a_k E_k` per basis profile ``k`` (S, S, K * C), each lit
        with its node's own oblique-incidence law and deposit depth."""
        entry, _, coefficients = self.surface(params, prepared, params.radiant.dtype)
        # d'Eon 2007 sec. 5.3: the colour layer on the way in
        E = entry_irradiance(params, prepared.texel_lights, coefficients, entry)
        if coefficients is not None:  # one irradiance per basis profile, a_k E_k, side by side in the channels
            E = E.reshape(E.shape[:-2] + (-1,))
        return E

    def diffusion(self, params, prepared: TexturePrepared, E):
        """Blurred irradiance per Gaussian (n, S, S, C), or the irradiance itself n times without diffusion.

        The blur is mask-normalised, which is right at UV seams (the surface goes on in another
        chart) but would keep, at an open surface's edge (a plane's rim), light that leaves
        there. So an open surface's texture is padded by ``prepared.open_margin`` texels of
        material without light (mask 1, irradiance 0, the edge's stretch): light that diffuses
        past the rim is carried off into the margin and only what comes back counts, as in the
        exact surface integral M(x) = int_object R(|x - y|) E(y) dy (tested across a plane's
        rim against the closed form; on the ketchup plane it took texture space from +6 % to
        within the path tracer's noise in red). With ``prepared.margin_kept`` the margin stays
        (n, S + 2m, S + 2m, C): a leg's step may read past the rim.
        """
        dtype = E.dtype
        if prepared.schedule is None:
            return jnp.broadcast_to(E, (params.variances.shape[0],) + E.shape)
        mask, m = jnp.asarray(prepared.texels.mask, dtype), prepared.open_margin
        stretch = jax.tree.map(lambda a: jnp.asarray(a, dtype), prepared.stretch)  # a (2,) pair, a map or (u, v)
        wrap_u = prepared.texels.wrap_u
        if m:
            rows = (m, m)
            cols = (0, 0) if wrap_u else (m, m)
            E = jnp.pad(E, (rows, cols, (0, 0)))
            mask = jnp.pad(mask, (rows, cols), constant_values=1.0)
            # Maps are extended by their edge; a scalar length (or a (2,) pair) holds for the margin too.
            stretch = jax.tree.map(lambda a: jnp.pad(a, (rows, cols) + ((0, 0),) * (a.ndim - 2), mode="edge")
                                   if a.ndim >= 2 else a, stretch)
        blurred = hierarchical_blur(E, mask, stretch, params.variances, prepared.schedule, taps=self.taps,
                                    wrap_u=wrap_u)
        if m and not prepared.margin_kept:
            blurred = blurred[:, m:-m, :] if wrap_u else blurred[:, m:-m, m:-m]
        return blurred

    def texel_exitance(self, params, prepared: TexturePrepared, blurred):
        """:math:`\\sum_i w_i B_i`, plus the translucent shadow maps' light when that pass runs (S, S, C) [W/mm^2];
        with parameter maps the basis profiles' weights on their own blurs, summed, and the light
        that crossed from one medium into another (:func:`jsss.render.surface_maps.crossing_light`);
        through the colour map's layer on the way out. With ``prepared.margin_kept``, (S + 2m, S + 2m, C)
        as the blurs it is given."""
        dtype = blurred.dtype
        weights = params.weights
        if prepared.coefficient_map is not None:  # sum_k sum_i W_ki G_i * (a_k E): the entry point's profile
            weights = params.maps.node_weights.astype(dtype)  # (K, n, C)
            weights = jnp.moveaxis(weights, 0, 1).reshape(weights.shape[1], -1)  # (n, K * C), as the channels
        M = jnp.einsum("nc,nhwc->hwc", weights, blurred)
        if prepared.translucent_shadow_maps:
            lights = [g.astype(dtype) for g in prepared.texel_lights]
            M = M + translucent_transmission(blurred, weights, params.variances, lights,
                                             jnp.asarray(prepared.texels.mask, dtype))
        _, exit_, coefficients = self.surface(params, prepared, dtype)
        if prepared.margin_kept and exit_ is not None:  # the colour layer read past the rim: the rim's
            m = prepared.open_margin
            exit_ = jnp.pad(exit_, ((m, m), (m, m)) + ((0, 0),) * (exit_.ndim - 2), mode="edge")
        if prepared.coefficient_map is not None:
            M = M.reshape(M.shape[:-1] + (-1, 3)).sum(-2)
            if params.maps.crosses():  # light that enters one medium and leaves another
                nodes = blurred.reshape(blurred.shape[:-1] + (-1, 3))
                M = M + crossing_light(nodes, coefficients, params.maps.node_crossing.astype(dtype))
        return scaled(M, exit_)  # and the colour layer on the way out

    def camera(self, params, prepared: TexturePrepared, M):
        """Radiance (H, W, 3): the texel exitance looked up at each pixel, through the camera pass.

        With the passes "last leg" and "first leg" each channel's subsurface light (diffusion and
        first bounce) is read where its legs moved it: the exitance at the moved point, and the
        first bounce scaled by the same ratio (:mod:`jsss.render.last_leg`,
        :mod:`jsss.render.first_leg`)."""
        exitance = self.pixel_lookup(prepared, M)
        if not self.moves_light(params, prepared):
            return camera_radiance(exitance, params, prepared.shading)
        moved = self.pixel_exitance(params, prepared, M)
        return camera_radiance(moved, params, prepared.shading, single_scale=moved_ratio(moved, exitance))

    @staticmethod
    def moves_light(params, prepared: TexturePrepared) -> bool:
        """Whether a leg's pass moves where the pixels read the exitance."""
        return (prepared.uv_per_mm is not None and params.last_leg is not None) or \
            (prepared.uv_jacobian is not None and params.first_leg is not None)

    @staticmethod
    def pixel_lookup(prepared: TexturePrepared, textures):
        """The textures (..., S, S, C) the stages carry read at each pixel's UV (..., H, W, C)."""
        scale, offset, mask = prepared.texture_reading()
        return lookup(textures, jnp.asarray(prepared.pixel_uv, textures.dtype) * scale + offset, mask)

    @classmethod
    def pixel_exitance(cls, params, prepared: TexturePrepared, textures):
        """The texel exitance ``textures`` (..., S, S, C) read at each pixel (..., H, W, C): at its
        UV, or where the legs' passes move each channel's light: the mean step of its last leg
        (every order's) farther from the eye (:mod:`jsss.render.last_leg`), and back toward the
        light by its first leg's (:mod:`jsss.render.first_leg`)."""
        if not cls.moves_light(params, prepared):
            return cls.pixel_lookup(prepared, textures)
        shading, dtype = prepared.shading, textures.dtype
        moves = 0.0
        if prepared.uv_per_mm is not None and params.last_leg is not None:
            steps = last_leg_steps(params.last_leg, shading.normal, shading.view, shading.lights, params.radiant,
                                   dtype, first_bounce_apart=False)
            moves = steps[..., None] * jnp.asarray(prepared.uv_per_mm, dtype)[..., None, :]    # (H, W, C, 2)
        scale, offset, mask = prepared.texture_reading()
        pixel_uv = jnp.asarray(prepared.pixel_uv, dtype) * scale + offset
        if prepared.uv_jacobian is None or params.first_leg is None:
            return moved_lookup(textures, pixel_uv, moves * scale, mask)
        first = first_leg_moves(params.first_leg, shading.normal, shading.view, shading.lights, params.radiant,
                                params.eta.astype(dtype), dtype)                          # (H, W, C, 3) mm
        first = jnp.einsum("hwij,hwcj->hwci", jnp.asarray(prepared.uv_jacobian, dtype), first)
        # The first leg's length spreads as a free path's: the exitance is averaged over its quantiles
        return sum(moved_lookup(textures, pixel_uv, (moves - q * first) * scale, mask)
                   for q in FIRST_LEG_QUANTILES) / len(FIRST_LEG_QUANTILES)

    def exitance(self, params, prepared: TexturePrepared):
        """Exitance per texel (S, S, C) [W/mm^2]: irradiance, diffusion, weighted sum (and
        translucency); a kept margin (``prepared.margin_kept``, the stages' own) cropped off."""
        M = self.texel_exitance(params, prepared, self.diffusion(params, prepared, self.irradiance(params, prepared)))
        m = prepared.open_margin if prepared.margin_kept else 0
        return M[m:-m, m:-m] if m else M

    def stages(self, prepared: TexturePrepared):
        return (("irradiance", lambda params, _: self.irradiance(params, prepared)),
                ("diffusion", lambda params, E: self.diffusion(params, prepared, E)),
                ("exitance + translucency", lambda params, blurred: self.texel_exitance(params, prepared, blurred)),
                ("camera", lambda params, M: self.camera(params, prepared, M)))

    def describe(self, plan) -> str:
        return (f"{len(plan.variances)} Gaussians (profile error {100 * plan.profile_error:.2f} %), "
                f"texture {self.size}^2, {self.taps}-tap blur, steps grow variance <= {self.max_ratio:g}x")

    def work(self, scene) -> int:
        return self.size * self.size
