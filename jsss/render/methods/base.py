r"""The interface every render method implements, and the camera pass they all end with.

As in Mitsuba 3 (one integrator per file behind ``ADIntegrator``), each method is an immutable
configuration in a file of its own -- :class:`~jsss.render.methods.Lambert`,
:class:`~jsss.render.methods.NormalFiltering`, :class:`~jsss.render.methods.ImageSpace`,
:class:`~jsss.render.methods.TextureSpace` -- whose fields are its knobs, checked when it is
built. The planner returns one (``plan.method_config``) and :func:`jsss.render.render` runs
whichever it is through this interface:

``prepare(scene, plan, params, *, timings=None) -> prepared``
    Everything that depends on the geometry alone (NumPy, once per scene and plan): the
    camera's G-buffer, shadow maps, texels or filtered normals, and which of the plan's
    passes run.
``stages(prepared) -> ((name, fn), ...)``
    The frame's JAX passes in order; ``fn(params, previous)`` returns what the next one
    reads, the last the radiance. :meth:`RenderMethod.radiance` runs them one after another
    (under one ``jit`` in :func:`~jsss.render.render`); ``render(..., time_passes=True)``
    compiles and times each on its own, under its name.
``exitance(params, prepared)``
    The light leaving the surface before the camera pass [W/mm^2] (per texel or per pixel).
``describe(plan)``, ``work(scene)``
    The knobs as :meth:`jsss.render.Plan.describe` prints them; the points a frame shades
    (pixels or texels), which the calibration's frame time scales with.

A prepared geometry (:class:`PreparedGeometry`) compares by the data it holds, so one compiled
frame serves a scene prepared again (:func:`jsss.render.frame_program`). Its expensive parts
(rasters, texels, shadow maps, the lights at them) are kept between frames while the mesh,
the camera and the lights' positions are the same (:func:`kept_camera`, :func:`kept_shadow_maps`,
:func:`kept_lights`; :mod:`jsss.render.memory`), so preparing a frame again costs milliseconds.

All methods end in :func:`camera_radiance`: the diffusion exitance :math:`M` of each pixel
spread by the exit lobe, single scattering taking its share, plus the specular lobe, times
the pixel's coverage (:func:`jsss.render.shading.frame_radiance`).
"""

from __future__ import annotations

import abc
import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...diffusion.exit_law import exit_law
from ...fresnel import exit_lobe
from ..environment import EnvironmentGeometry
from ..image_space import camera_buffers
from ..lighting import irradiance, light_geometry, node_irradiance, shadow_map
from ..memory import camera_key, digest, kept, light_key, mesh_key
from ..passes import Method, Pass
from ..raster import surface_attributes
from ..shading import (
    angular_exit_lobe,
    frame_radiance,
    single_scattering,
    specular_radiance,
)
from ..surface_maps import MapSampler, read_points, scaled

if TYPE_CHECKING:
    from ..planner import Plan
    from ..renderer import RenderParams
    from ..scene import Scene

__all__ = ["PixelShading", "PreparedGeometry", "RenderMethod", "camera_parts", "camera_radiance", "entry_irradiance",
           "kept_camera", "kept_lights", "kept_shadow_maps", "pixel_shading"]


def kept_camera(scene: Scene):
    """The camera's G-buffer of ``scene`` (:func:`jsss.render.camera_buffers`), kept while the mesh
    and the camera are the same (:mod:`jsss.render.memory`)."""
    return kept("camera buffers", (mesh_key(scene.mesh), camera_key(scene.camera)),
                lambda: camera_buffers(scene.mesh, scene.camera))


def kept_shadow_maps(scene: Scene) -> list:
    """Each light's shadow map (:func:`jsss.render.lighting.shadow_map`), kept while the mesh, the
    light's position (direction, map) and the map's size are the same."""
    mesh, size = scene.mesh, scene.shadow_map_size
    return [kept("shadow map", (mesh_key(mesh), light_key(light), size),
                 functools.partial(shadow_map, mesh, light, size=size)) for light in scene.lights]


def kept_lights(scene: Scene, where, positions, normals, valid, maps) -> tuple:
    """Each light's :class:`~jsss.render.lighting.LightGeometry` at the points ``positions``,
    ``normals``, ``valid`` (from the kept texels or camera buffers that ``where`` names, a
    digest or tuple of the inputs they come from), against its shadow map of ``maps``."""
    mesh_id, size = mesh_key(scene.mesh), scene.shadow_map_size
    return tuple(kept("light geometry", (where, mesh_id, light_key(light), size),
                      functools.partial(light_geometry, positions, normals, valid, light, m))
                 for light, m in zip(scene.lights, maps, strict=True))


class PreparedGeometry:
    """What a method's ``prepare`` returns (a frozen dataclass of NumPy data) is equal to another
    holding the same data: equality and hash by a digest of every array and value in it, so a
    frame compiled for one serves an equal one prepared again (:func:`jsss.render.render`)."""

    @functools.cached_property
    def digest(self) -> str:
        """BLAKE2 digest of the data (computed once; the kept geometry's arrays are read-only and
        their digests remembered, :mod:`jsss.render.memory`, so a frame prepared again from them
        is digested in milliseconds)."""
        return digest(self)

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and other.digest == self.digest

    def __hash__(self) -> int:
        return hash(self.digest)


@dataclass(frozen=True, eq=False)
class PixelShading:
    """What the camera pass reads per pixel, and which of its passes run (NumPy, fixed for a frame).

    Attributes
    ----------
    normal : (H, W, 3) unit normals, turned towards the camera
    view : (H, W, 3) unit directions from the surface point to the eye
    coverage : (H, W) share of each pixel the surface covers (the frame's radiance is weighted by it)
    lights : tuple of LightGeometry at the pixels, one per light
    single_scattering, specular : bool, whether the plan runs these passes
    roughness : float, Beckmann slope RMS m; specular_weight : float, scales the lobe
    colour_map, coefficient_map : MapSampler or None, where each pixel reads the material's colour
        map (bilinearly) and parameter maps (the texel it falls in, :meth:`MapSampler.at`)
        (:mod:`jsss.render.surface_maps`)
    """

    normal: np.ndarray
    view: np.ndarray
    coverage: np.ndarray
    lights: tuple
    single_scattering: bool
    specular: bool
    roughness: float
    specular_weight: float
    colour_map: MapSampler | None = None
    coefficient_map: MapSampler | None = None

    @property
    def static_fields(self) -> tuple:
        """An environment's specular lobe reads the normals and view directions in NumPy
        (:func:`jsss.render.environment.environment_specular`): then they are constants of the
        compiled frame, not its arguments (:mod:`jsss.render.programs`)."""
        if self.specular and any(isinstance(g, EnvironmentGeometry) for g in self.lights):
            return ("normal", "view")
        return ()


def pixel_shading(scene: Scene, plan: Plan, buffers, lights) -> PixelShading:
    """The camera pass's data for ``scene`` under ``plan``, from the camera's G-buffer and the lights at it."""
    material = scene.material
    colour_map = coefficient_map = None
    maps = material.maps
    if maps is not None:
        wrap, at = scene.mesh.wrap_u, (mesh_key(scene.mesh), camera_key(scene.camera))

        def sampler(shape, nearest):  # kept while the mesh, camera and map size stay
            return kept("pixel map sampler", (at, shape, nearest), lambda: MapSampler.at(
                surface_attributes(buffers.raster, scene.mesh.faces, scene.mesh.uvs), shape, wrap_u=wrap,
                nearest=nearest))

        if maps.colour is not None:
            colour_map = sampler(maps.colour.shape[:2], False)
        if maps.parametric:
            # Each map texel is one medium (surface_maps.crossing_light says why)
            coefficient_map = sampler(maps.sigma_a.shape[:2], True)
    return PixelShading(buffers.normal, buffers.view, buffers.coverage, tuple(lights),
                        plan.on(Pass.SINGLE_SCATTERING), plan.on(Pass.SPECULAR), material.roughness,
                        material.specular, colour_map, coefficient_map)


def entry_irradiance(params: RenderParams, lights, coefficients=None, entry=None, *, law=None):
    r"""The light that enters the medium at each point [W/mm^2]: the transmitted irradiance
    (:func:`jsss.render.lighting.irradiance`, with the plan's oblique-incidence law and deposit
    depth) through the colour layer's ``entry`` factor, shape (..., C).

    With parameter maps (``coefficients`` (..., K, C), the points' blend weights) it is
    :math:`a_k E_k` per basis node, shape (..., K, C): each node lit with its *own* law and
    deposit depth (:func:`jsss.render.lighting.node_irradiance`), so that a texel of skin beside
    one of marble returns oblique light as skin does. ``law``: the homogeneous medium's law,
    solved already (normal filtering lights a frame once per channel).
    """
    dtype = params.radiant.dtype
    lights = [g.astype(dtype) for g in lights]
    if coefficients is None:
        medium = None if law is not None else params.oblique
        return scaled(irradiance(lights, params.radiant, params.eta, medium=medium, deposit=params.deposit,
                                 law=law), entry)
    E = node_irradiance(lights, params.radiant, params.eta, params.maps.node_media,
                        oblique=params.oblique is not None, deposit=params.deposit is not None)
    return coefficients * scaled(E, None if entry is None else entry[..., None, :])


def camera_parts(params: RenderParams, shading: PixelShading, dtype, *, medium=None):
    r"""The camera pass's per-pixel parts besides the exitance, in ``dtype``: ``(exit_lobe,
    single_scattering, specular)``.

    ``exit_lobe`` (H, W, C) [1/sr] is :math:`F_t(\cos\theta_o, \eta)/(\pi(1 - F_{dr,ext}))`
    (:func:`jsss.fresnel.exit_lobe`), or where the plan runs the exit-angle pass Chandrasekhar's
    lobe of the light arriving at the pixel, of the second and later bounces when the first runs
    apart (:func:`jsss.render.shading.angular_exit_lobe`); ``single_scattering`` the pair (radiance [W/(mm^2 sr)],
    exitance [W/mm^2]) of Jensen 2001's first bounce (:func:`jsss.render.shading.single_scattering`)
    of ``medium`` (default the parameters' own), or None when the plan does not run it or the
    material is not a homogeneous medium; ``specular`` the Beckmann lobe [W/(mm^2 sr)], or None
    when the plan does not run it.
    """
    cos_view = jnp.asarray((shading.normal * shading.view).sum(-1), dtype)
    lights = [g.astype(dtype) for g in shading.lights]
    single = None
    if shading.single_scattering and params.medium is not None:
        normal, view = jnp.asarray(shading.normal, dtype), jnp.asarray(shading.view, dtype)
        _, _, coefficients = read_points(params.maps, None, shading.coefficient_map, dtype)
        if coefficients is None:
            single = single_scattering(params.medium if medium is None else medium, normal, view, lights,
                                       params.radiant, deposit=params.deposit)
        else:  # Jensen 2001 ("Texture"): the parameters at the exit point, blended from the basis' media
            nodes = params.maps.node_media
            single = (0.0, 0.0)
            for k in range(coefficients.shape[-2]):
                node = jax.tree_util.tree_map(lambda a: a[k], nodes)
                radiance, exitance = single_scattering(node, normal, view, lights, params.radiant,
                                                       deposit=None if params.deposit is None else node)
                share = coefficients[..., k, :]
                single = (single[0] + share * radiance, single[1] + share * exitance)
        single = _surface_layer(single, params, shading, dtype)
    if params.exit_angle is None:
        lobe = exit_lobe(cos_view[..., None], params.eta)
    else:  # the pass "exit angle": the lobe of the light that arrives here (the first bounce's own when apart)
        law = exit_law(params.exit_angle, first_bounce_apart=single is not None)
        lobe = angular_exit_lobe(law, cos_view, lights, params.radiant, params.eta)
    specular = None
    if shading.specular:
        specular = specular_radiance(shading.normal, shading.view, lights, params.radiant, params.eta,
                                     roughness=shading.roughness, weight=shading.specular_weight)
    return lobe, single, specular


def _surface_layer(single, params: RenderParams, shading: PixelShading, dtype):
    """Single scattering under the colour map (it crosses the layer in and out at one point: times
    :math:`c(x)`, whatever the texturing) and the profile's normalisation to white."""
    maps = params.maps
    if maps is None:
        return single
    scale = 1.0
    if maps.albedo is not None and shading.colour_map is not None:
        scale = shading.colour_map(maps.albedo.astype(dtype))
    if maps.single_scale is not None:
        scale = scale * maps.single_scale
    return single[0] * scale, single[1] * scale


def camera_radiance(exitance, params: RenderParams, shading: PixelShading, *, single_scale=None):
    r"""Linear radiance (H, W, 3) [W/(mm^2 sr)] toward the camera of the diffusion exitance
    ``exitance`` (H, W, C) [W/mm^2] of each pixel's surface point.

    .. math:: L = c\,\bigl(\max(M - M^{(1)}, 0)\,\Lambda(\theta_o) + L^{(1)} + L_s\bigr),
              \qquad \Lambda = \frac{F_t(\cos\theta_o, \eta)}{\pi\,(1 - F_{dr,ext})},

    with the exit lobe :math:`\Lambda` [1/sr], Jensen 2001's single-scattered radiance
    :math:`L^{(1)}` and exitance :math:`M^{(1)}` of the medium when the pass runs (it replaces its
    share of the diffusion light: :func:`jsss.render.shading.surface_radiance`), the specular
    lobe :math:`L_s` when it runs, and the pixel's coverage :math:`c` (:func:`camera_parts`,
    :func:`jsss.render.shading.frame_radiance`). ``single_scale`` (H, W, C): the first bounce's
    radiance and exitance times it (the pass "last leg", :mod:`jsss.render.last_leg`).
    """
    dtype = exitance.dtype
    lobe, single, specular = camera_parts(params, shading, dtype)
    if single is not None and single_scale is not None:
        single = (single[0] * single_scale, single[1] * single_scale)
    return frame_radiance(exitance, lobe, jnp.asarray(shading.coverage, dtype), single_scattering=single,
                          specular=specular)


class RenderMethod(eqx.Module):
    """A way to produce a frame's subsurface light: an immutable configuration (abstract).

    Subclasses are final: their fields are the method's knobs (static, so a configuration is
    hashable and equal configurations compile to one program), checked in ``__check_init__``
    with a ``ValueError`` naming the knob, its value and the fix.
    """

    method: eqx.AbstractClassVar[Method]  # set by each final subclass: the enumeration member it implements

    @abc.abstractmethod
    def prepare(self, scene: Scene, plan: Plan, params: RenderParams, *, timings: dict | None = None):
        """Everything of ``scene`` under ``plan`` that depends on the geometry alone (NumPy).

        ``params`` (:func:`jsss.render.render_params`) is read where a method's geometry depends on
        the profile (normal filtering's filtered normals, image-space's sampling disc). Seconds
        of each step are added to ``timings``.
        """

    @abc.abstractmethod
    def stages(self, prepared) -> tuple[tuple[str, Callable], ...]:
        """The frame's JAX passes in order, ``(name, fn)`` with ``fn(params, previous) -> next``;
        the first reads ``previous = None``, the last returns the radiance (H, W, 3)."""

    @abc.abstractmethod
    def exitance(self, params: RenderParams, prepared):
        """Light leaving the surface before the camera pass [W/mm^2], per texel or per pixel (..., C)."""

    @abc.abstractmethod
    def describe(self, plan: Plan) -> str:
        """The knobs as :meth:`jsss.render.Plan.describe` prints them (after ``knobs: ``)."""

    @abc.abstractmethod
    def work(self, scene: Scene) -> int:
        """Points a frame shades (pixels, or texels): what the calibration's frame time scales with."""

    def radiance(self, params: RenderParams, prepared):
        """Linear radiance (H, W, 3) of a prepared frame: its :meth:`stages` one after another.
        A pure JAX function of ``params`` (``jit`` and ``grad`` go through it)."""
        out = None
        for _, stage in self.stages(prepared):
            out = stage(params, out)
        return out
