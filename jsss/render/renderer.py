"""Run a plan: the method's static geometry once (NumPy), then its differentiable JAX passes.

The plan carries the method as an immutable configuration (``plan.method_config``, one of
:mod:`jsss.render.methods`); :func:`render` runs whichever it is through their common
interface: ``prepare`` computes everything that depends only on geometry (texel positions,
shadow maps, the camera's visibility), and the method's stages are a pure JAX function of
:class:`RenderParams` -- the material's Gaussian weights and variances and the lights'
radiant colours -- so ``jit`` and ``grad`` go through them. :func:`render` is the
convenience that does both and can time each stage.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..medium import Medium
from .image_space import SampledProfile
from .methods import PixelPrepared, TexturePrepared
from .passes import Pass
from .planner import Plan, plan_scene
from .profiles import render_profile
from .scene import Scene
from .surface_maps import MapParams

__all__ = ["RenderParams", "RenderResult", "frame_program", "prepare", "render", "render_image", "render_params"]


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
    maps : MapParams or None, the material's colour and parameter maps and the basis profiles
        they blend (:mod:`jsss.render.surface_maps`); differentiable in every texel
    """

    weights: jax.Array
    variances: jax.Array
    radiant: jax.Array
    eta: jax.Array
    profile: SampledProfile
    medium: Medium | None = None
    oblique: Medium | None = None
    deposit: Medium | None = None
    maps: MapParams | None = None


def map_params(scene: Scene, plan: Plan, total, dtype) -> MapParams | None:
    """The scene's maps as a frame reads them (None for a homogeneous material whose profile is
    not normalised); ``total`` (3,) is the profile's own total, which normalising divides out."""
    material = scene.material
    maps = material.maps
    if maps is None and not material.normalize_profile:
        return None
    fields = {}
    if material.normalize_profile:
        fields["single_scale"] = 1.0 / total
    if maps is not None:
        fields["texturing"] = maps.texturing
        if maps.colour is not None:
            fields["albedo"] = maps.colour
        if maps.parametric:
            basis = plan.basis
            if basis is None:
                raise ValueError("the material has parameter maps but the plan has no basis profiles; plan the scene "
                                 "with plan_scene (which chooses them).")
            media = basis.media(material.eta)
            fields |= dict(sigma_a=maps.sigma_a, sigma_s_prime=maps.sigma_s_prime, scale_nodes=basis.scale_nodes,
                           shape_nodes=basis.shape_nodes, node_weights=basis.weights, node_media=media,
                           node_crossing=basis.crossing)
    fields = {k: v if isinstance(v, str) else jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), v)
              for k, v in fields.items()}
    return MapParams(**fields)


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
    total = weights.sum(0)
    if scene.material.normalize_profile:  # d'Eon 2007 sec. 5.3: the colour map alone sets the colour
        weights = weights / total
    medium = scene.material.medium if medium is None else medium
    if medium is not None and scene.material.kind == "medium":
        medium = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), medium)
    else:
        medium = None
    if medium is not None and scene.material.profile_model == "dipole" and not scene.material.normalize_profile:
        # Image-space sampling draws from the dipole exactly; any other profile model is
        # sampled through its Gaussian-sum fit (which matches the model's exact profile).
        profile = SampledProfile(medium=medium)
    else:
        profile = SampledProfile(weights=weights, variances=variances)
    oblique = medium if medium is not None and plan.on(Pass.OBLIQUE_INCIDENCE) else None
    deposit = medium if medium is not None and plan.on(Pass.DEPOSIT_DEPTH) else None
    return RenderParams(weights, variances, jnp.asarray(radiant, dtype), eta.astype(dtype), profile, medium, oblique,
                        deposit, map_params(scene, plan, total, dtype))


def prepare(scene: Scene, plan: Plan, *, dtype=jnp.float32, timings: dict | None = None):
    """Geometry-only data of ``scene`` under ``plan``: ``plan.method_config.prepare`` with the
    parameters :func:`render` would use (``dtype``: a pixel method's filter or sampling disc is
    computed from the profile in it)."""
    return plan.method_config.prepare(scene, plan, render_params(scene, plan, dtype=dtype), timings=timings)


def render_image(params: RenderParams, prepared, plan: Plan):
    """Linear radiance (H, W, 3) of a prepared scene: a pure function of ``params``."""
    return plan.method_config.radiance(params, prepared)


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered frame: linear radiance, the plan it followed and seconds per pass."""

    radiance: np.ndarray
    plan: Plan
    timings: dict
    prepared: TexturePrepared | PixelPrepared


def _timed(fn, *args, repeats: int):
    fn(*args)  # compile
    best = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        best.append(time.perf_counter() - t0)
    return out, float(np.median(best))


FRAME_PROGRAMS = 4  # compiled frames kept, the most recently used


@functools.lru_cache(maxsize=FRAME_PROGRAMS)
def frame_program(method, prepared):
    """The jitted frame ``params -> radiance`` of a method configuration and its prepared geometry.

    Kept for the last ``FRAME_PROGRAMS`` pairs: both compare by value (a configuration by its
    knobs, a prepared geometry by a digest of its data), so rendering a scene and plan again
    prepares them again but neither traces nor compiles (the geometry stays a constant of the
    program, as in a frame compiled afresh: the same numbers to the last bit).
    """
    return jax.jit(lambda params: method.radiance(params, prepared))


def render(scene: Scene, plan: Plan | None = None, *, dtype=jnp.float32, time_passes: bool = False,
           repeats: int = 3) -> RenderResult:
    """Plan (unless given), prepare and render ``scene``.

    With ``time_passes`` every stage of the method is compiled first and timed (median of
    ``repeats``); otherwise the whole frame runs as one jitted function, compiled once for the
    method's configuration and the prepared geometry (:func:`frame_program`): a frame of the
    same scene and plan again does not recompile.
    """
    timings: dict = {}
    if plan is None:
        t0 = time.perf_counter()
        plan = plan_scene(scene)
        timings["plan"] = time.perf_counter() - t0
    method = plan.method_config
    params = render_params(scene, plan, dtype=dtype)
    prepared = method.prepare(scene, plan, params, timings=timings)
    if not time_passes:
        frame = frame_program(method, prepared)
        t0 = time.perf_counter()
        radiance = np.asarray(frame(params))
        timings["frame (with compile)"] = time.perf_counter() - t0
        return RenderResult(radiance, plan, timings, prepared)
    out = None
    for name, stage in method.stages(prepared):
        out, timings[name] = _timed(jax.jit(stage), params, out, repeats=repeats)
    return RenderResult(np.asarray(out), plan, timings, prepared)
