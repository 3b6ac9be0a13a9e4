"""Run a plan: static geometry once (NumPy), then the differentiable JAX passes.

Texture-space plans run the passes below; the pixel methods (Lambert, normal filtering,
image-space) run :mod:`.pixel_methods`.

:func:`prepare` computes everything that depends only on geometry (texel positions,
shadow maps, the camera's visibility); :func:`render_image` is a pure JAX function of the
material's Gaussian weights and variances and the lights' radiant colours, so ``jit``
and ``grad`` go through it. :func:`render` is the convenience that does both and can time
each pass.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..medium import Medium
from .blur import blur_schedule, hierarchical_blur, uniform_stretch
from .image_space import SampledProfile, camera_buffers
from .lighting import irradiance, light_geometry, lookup, shadow_map, translucent_transmission
from .mesh import is_closed
from .passes import Method, Pass
from .pixel_methods import PixelPrepared, pixel_radiance, prepare_pixels
from .planner import Plan, plan_scene
from .profiles import render_profile
from .raster import surface_attributes
from .scene import Scene
from .shading import specular_radiance, surface_radiance
from .texture_space import TexelGeometry, bake_texels

__all__ = ["Prepared", "RenderParams", "RenderResult", "prepare", "render", "render_image", "render_params"]


class RenderParams(eqx.Module):
    """The differentiable inputs of a frame.

    Attributes
    ----------
    weights : (n, 3) Gaussian weights per channel; variances : (n,) [mm^2]
    radiant : (L, 3) colour times intensity of each light
    eta : (3,) relative index of refraction
    profile : SampledProfile, the exact profile the pixel methods integrate (the dipole of a
        homogeneous material, else the Gaussian sum above)
    medium : Medium or None, a homogeneous material's medium (for the single-scattering pass)
    oblique : Medium or None, the medium whose oblique-incidence law scales the irradiance
        (:func:`jsss.diffusion.incidence.incidence_ratio`), when the plan turns that pass on
    deposit : Medium or None, the medium whose deposit depth point lights are read at
        (:func:`jsss.render.lighting.depth_falloff`), when the plan turns that pass on
    """

    weights: jax.Array
    variances: jax.Array
    radiant: jax.Array
    eta: jax.Array
    profile: SampledProfile
    medium: Medium | None = None
    oblique: Medium | None = None
    deposit: Medium | None = None


def render_params(scene: Scene, plan: Plan, *, medium=None, dtype=jnp.float32, radii=None) -> RenderParams:
    """Parameters of ``scene`` under ``plan``; ``medium`` replaces a homogeneous material's medium
    (pass a traced one to differentiate with respect to sigma_a, sigma_s' or eta). ``radii``
    [mm], where the render profile is fitted (default: from the scene's own profile), must
    be given when this runs under ``jit``."""
    gs = render_profile(scene.material, plan.variances, medium=medium, radii=radii)
    radiant = np.array([np.asarray(l.color) * l.intensity for l in scene.lights])
    eta = scene.material.eta if medium is None else medium.eta
    eta = jnp.broadcast_to(jnp.asarray(eta), (3,))
    weights, variances = jnp.asarray(gs.weights, dtype), jnp.asarray(gs.variances, dtype)
    medium = scene.material.medium if medium is None else medium
    if medium is not None and scene.material.kind == "medium":
        medium = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), medium)
    else:
        medium = None
    if medium is not None and scene.material.profile_model == "dipole":
        # Image-space sampling draws from the dipole exactly; any other profile model is
        # sampled through its Gaussian-sum fit (which matches the model's exact profile).
        profile = SampledProfile(medium=medium)
    else:
        profile = SampledProfile(weights=weights, variances=variances)
    oblique = medium if medium is not None and plan.on(Pass.OBLIQUE_INCIDENCE) else None
    deposit = medium if medium is not None and plan.on(Pass.DEPOSIT_DEPTH) else None
    return RenderParams(weights, variances, jnp.asarray(radiant, dtype), eta.astype(dtype), profile, medium, oblique,
                        deposit)


@dataclass(frozen=True, eq=False)
class Prepared:
    """Geometry-only data of a scene under a plan (NumPy arrays)."""

    texels: TexelGeometry
    texel_lights: tuple
    pixel_mask: np.ndarray
    pixel_coverage: np.ndarray  # (H, W) share of each pixel the surface covers: the frame's radiance is weighted by it
    pixel_uv: np.ndarray
    pixel_normal: np.ndarray
    pixel_view: np.ndarray
    pixel_lights: tuple
    stretch: np.ndarray | tuple  # (H, W, 2), a (2,) pair, or a (u, v) tuple of scalars and maps
    schedule: object
    open_margin: int = 0  # unlit texels padded around the texture of an open surface (see diffusion_pass)


def prepare(scene: Scene, plan: Plan, *, timings: dict | None = None) -> Prepared:
    """Bake texels, shadow maps and the camera's visibility for ``scene`` at ``plan``'s sizes."""
    timings = {} if timings is None else timings
    t0 = time.perf_counter()
    texels = bake_texels(scene.mesh, plan.texture_size)
    timings["texture geometry"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    maps = [shadow_map(scene.mesh, light, size=scene.shadow_map_size) for light in scene.lights]
    texel_lights = tuple(light_geometry(texels.position, texels.normal, texels.mask, light, m)
                         for light, m in zip(scene.lights, maps))
    timings["shadows"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    camera = camera_buffers(scene.mesh, scene.camera)  # two-sided: normals turned towards the camera
    mask, normal, view = camera.mask, camera.normal, camera.view
    uv = surface_attributes(camera.raster, scene.mesh.faces, scene.mesh.uvs)
    pixel_lights = tuple(light_geometry(camera.position, normal, mask, light, m)
                         for light, m in zip(scene.lights, maps))
    timings["camera raster"] = time.perf_counter() - t0
    if plan.on(Pass.STRETCH_CORRECTION):
        stretch = texels.stretch
    else:  # uniform: the median texel length everywhere
        stretch = np.where(texels.mask[..., None], texels.median_stretch(), 0.0)
    # A scalar per axis whose texels all have one length (a plane's both, a sphere's v): the blur
    # then reads that axis's taps as slices, not gathers (decided here: in the jitted passes the
    # map is traced).
    stretch = uniform_stretch(stretch, texels.mask)
    schedule = blur_schedule(np.asarray(plan.variances), texels.median_stretch(), max_ratio=plan.max_ratio) \
        if plan.on(Pass.DIFFUSION) else None
    margin = 0
    if schedule is not None and not is_closed(scene.mesh):
        reach = 3.0 * np.sqrt(float(np.max(plan.variances))) / texels.median_stretch()
        margin = int(min(np.ceil(reach), texels.size // 4))
    return Prepared(texels, texel_lights, mask, camera.coverage, uv, normal, view, pixel_lights, stretch, schedule,
                    margin)


def irradiance_pass(params: RenderParams, prep: Prepared):
    lights = [g.astype(params.radiant.dtype) for g in prep.texel_lights]
    return irradiance(lights, params.radiant, params.eta, medium=params.oblique, deposit=params.deposit)


def diffusion_pass(params: RenderParams, prep: Prepared, plan: Plan, E):
    """Blurred irradiance per Gaussian (n, S, S, 3), or the irradiance itself n times without diffusion.

    The blur is mask-normalised, which is right at UV seams (the surface goes on in another
    chart) but would keep, at an open surface's edge (a plane's rim), light that leaves
    there. So an open surface's texture is padded by ``prep.open_margin`` texels of material
    without light (mask 1, irradiance 0, the edge's stretch): light that diffuses past the rim
    is carried off into the margin and only what comes back counts, as in the exact surface
    integral M(x) = int_object R(|x - y|) E(y) dy (tested across a plane's rim against the
    closed form; on the ketchup plane it took texture space from +6 % to within the path
    tracer's noise in red).
    """
    dtype = E.dtype
    if not plan.on(Pass.DIFFUSION):
        return jnp.broadcast_to(E, (len(plan.variances),) + E.shape)
    mask, m = jnp.asarray(prep.texels.mask, dtype), prep.open_margin
    stretch = jax.tree.map(lambda a: jnp.asarray(a, dtype), prep.stretch)  # a (2,) pair, a map or a (u, v) tuple
    if m:
        rows = (m, m)
        cols = (0, 0) if prep.texels.wrap_u else (m, m)
        E = jnp.pad(E, (rows, cols, (0, 0)))
        mask = jnp.pad(mask, (rows, cols), constant_values=1.0)
        # Maps are extended by their edge; a scalar length (or a (2,) pair) holds for the margin too.
        stretch = jax.tree.map(lambda a: jnp.pad(a, (rows, cols) + ((0, 0),) * (a.ndim - 2), mode="edge")
                               if a.ndim >= 2 else a, stretch)
    blurred = hierarchical_blur(E, mask, stretch, params.variances, prep.schedule, taps=plan.taps,
                                wrap_u=prep.texels.wrap_u)
    if m:
        blurred = blurred[:, m:-m, :] if prep.texels.wrap_u else blurred[:, m:-m, m:-m]
    return blurred


def exitance_pass(params: RenderParams, prep: Prepared, plan: Plan, blurred):
    M = jnp.einsum("nc,nhwc->hwc", params.weights, blurred)
    if plan.on(Pass.TRANSLUCENT_SHADOW_MAPS):
        lights = [g.astype(blurred.dtype) for g in prep.texel_lights]
        M = M + translucent_transmission(blurred, params.weights, params.variances, lights,
                                         jnp.asarray(prep.texels.mask, blurred.dtype))
    return M


def camera_pass(params: RenderParams, prep: Prepared, plan: Plan, M, roughness: float, specular: float):
    dtype = M.dtype
    coverage = jnp.asarray(prep.pixel_coverage, dtype)
    exitance = lookup(M, prep.pixel_uv, prep.texels.mask)
    cos_view = jnp.asarray((prep.pixel_normal * prep.pixel_view).sum(-1), dtype)
    lights = [g.astype(dtype) for g in prep.pixel_lights]
    single = plan.on(Pass.SINGLE_SCATTERING) and params.medium is not None
    L = surface_radiance(exitance, cos_view, params.eta, medium=params.medium if single else None,
                         normals=jnp.asarray(prep.pixel_normal, dtype), view_dirs=jnp.asarray(prep.pixel_view, dtype),
                         light_geometry=lights, radiant=params.radiant, deposit=params.deposit)
    if plan.on(Pass.SPECULAR):
        L = L + specular_radiance(prep.pixel_normal, prep.pixel_view, lights, params.radiant,
                                  params.eta, roughness=roughness, weight=specular)
    return L * coverage[..., None]


def render_image(params: RenderParams, prep: Prepared, plan: Plan, *, roughness: float = 0.35,
                 specular: float = 1.0):
    """Linear radiance (H, W, 3) of a prepared scene: a pure function of ``params``."""
    E = irradiance_pass(params, prep)
    blurred = diffusion_pass(params, prep, plan, E)
    M = exitance_pass(params, prep, plan, blurred)
    return camera_pass(params, prep, plan, M, roughness, specular)


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered frame: linear radiance, the plan it followed and seconds per pass."""

    radiance: np.ndarray
    plan: Plan
    timings: dict
    prepared: Prepared | PixelPrepared


def _timed(fn, *args, repeats: int):
    fn(*args)  # compile
    best = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        best.append(time.perf_counter() - t0)
    return out, float(np.median(best))


def render(scene: Scene, plan: Plan | None = None, *, dtype=jnp.float32, time_passes: bool = False,
           repeats: int = 3) -> RenderResult:
    """Plan (unless given), prepare and render ``scene``.

    With ``time_passes`` every JAX pass is compiled first and timed (median of ``repeats``);
    otherwise the whole frame runs as one jitted function.
    """
    timings: dict = {}
    if plan is None:
        t0 = time.perf_counter()
        plan = plan_scene(scene)
        timings["plan"] = time.perf_counter() - t0
    material = scene.material
    if plan.method != Method.TEXTURE_SPACE:
        return _render_pixels(scene, plan, dtype=dtype, timings=timings, time_passes=time_passes, repeats=repeats)
    prep = prepare(scene, plan, timings=timings)
    params = render_params(scene, plan, dtype=dtype)
    if not time_passes:
        frame = jax.jit(lambda p: render_image(p, prep, plan, roughness=material.roughness,
                                               specular=material.specular))
        t0 = time.perf_counter()
        radiance = np.asarray(frame(params))
        timings["frame (with compile)"] = time.perf_counter() - t0
        return RenderResult(radiance, plan, timings, prep)
    E, timings["irradiance"] = _timed(jax.jit(lambda p: irradiance_pass(p, prep)), params, repeats=repeats)
    blurred, timings["diffusion"] = _timed(jax.jit(lambda p, e: diffusion_pass(p, prep, plan, e)), params, E,
                                           repeats=repeats)
    M, timings["exitance + translucency"] = _timed(jax.jit(lambda p, b: exitance_pass(p, prep, plan, b)),
                                                   params, blurred, repeats=repeats)
    radiance, timings["camera"] = _timed(
        jax.jit(lambda p, m: camera_pass(p, prep, plan, m, material.roughness, material.specular)), params, M,
        repeats=repeats)
    return RenderResult(np.asarray(radiance), plan, timings, prep)


def _render_pixels(scene: Scene, plan: Plan, *, dtype, timings: dict, time_passes: bool, repeats: int):
    params = render_params(scene, plan, dtype=dtype)
    prep = prepare_pixels(scene, plan.method, params.profile, normal_filter=plan.normal_filter, timings=timings)
    material = scene.material
    frame = jax.jit(lambda p: pixel_radiance(plan.method, p.profile, p.radiant, p.eta, prep, samples=plan.samples,
                                             oblique=p.oblique, deposit=p.deposit,
                                             specular=plan.on(Pass.SPECULAR), roughness=material.roughness,
                                             specular_weight=material.specular,
                                             single_scattering=plan.on(Pass.SINGLE_SCATTERING), medium=p.medium))
    if time_passes:
        radiance, timings[f"{plan.method} frame"] = _timed(frame, params, repeats=repeats)
    else:
        t0 = time.perf_counter()
        radiance = frame(params)
        timings["frame (with compile)"] = time.perf_counter() - t0
    return RenderResult(np.asarray(radiance), plan, timings, prep)
