"""Run a plan: the method's static geometry once (NumPy), then its differentiable JAX passes.

The plan carries the method as an immutable configuration (``plan.method_config``, one of
:mod:`jsss.render.methods`); :func:`render` runs whichever it is through their common
interface: ``prepare`` computes everything that depends only on geometry (texel positions,
shadow maps, the camera's visibility), and the method's stages are a pure JAX function of
:class:`RenderParams` -- the material's Gaussian weights and variances and the lights'
radiant colours -- so ``jit`` and ``grad`` go through them. :func:`render` is the
convenience that does both and can time each stage.

Warm frames cost their passes: the geometry's rasters, texels and shadow maps are kept while
the mesh, the camera and the lights' positions stay (:mod:`jsss.render.memory`), and the
compiled frame takes the geometry's arrays as arguments, so one program serves every frame of
the same layout (:mod:`jsss.render.programs`, :func:`frame_program`).
:func:`jsss.render.prepare_renderer` readies a scene for a loop over materials or intensities.
"""

from __future__ import annotations

import functools
import time
import weakref
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..medium import Medium
from ..numerics import device_array, is_concrete
from . import programs
from .image_space import SampledProfile
from .methods import PixelPrepared, TexturePrepared
from .passes import Pass
from .planner import Plan, plan_scene
from .profiles import render_profile
from .scene import Scene
from .surface_maps import MapParams

__all__ = ["FrameProgram", "RenderParams", "RenderResult", "frame_program", "light_radiant", "prepare", "render",
           "render_image", "render_params"]


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
    exit_angle : Medium or None, the medium whose exit law (Chandrasekhar's kernel,
        :mod:`jsss.diffusion.exit_law`) spreads the exitance over angles, when the plan turns that
        pass on; else the flat diffusion lobe (:func:`jsss.fresnel.exit_lobe`)
    last_leg : Medium or None, the medium whose last leg below the surface moves where the camera
        reads the exitance (:mod:`jsss.render.last_leg`), when the plan turns that pass on
    first_leg : Medium or None, the medium whose first leg below the surface moves where the light
        is deposited (:mod:`jsss.render.first_leg`), when the plan turns that pass on
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
    exit_angle: Medium | None = None
    last_leg: Medium | None = None
    first_leg: Medium | None = None


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


def light_radiant(lights, dtype=jnp.float32):
    """(L, 3) each light's colour times its intensity, in ``dtype`` (:attr:`RenderParams.radiant`)."""
    return device_array(np.array([np.asarray(light.color) * light.intensity for light in lights], np.dtype(dtype)))


_profiles: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # material -> {(variances, x64): GaussianSum}


def _scene_profile(material, variances):
    """:func:`jsss.render.profiles.render_profile` of a material (a frozen object: its profile
    does not change) on ``variances``, fitted once per material and variances: a warm frame of
    a small object would otherwise spend a tenth of its time refitting it."""
    variances = np.asarray(variances)
    key = (variances.dtype.str, variances.tobytes(), bool(jax.config.jax_enable_x64))
    known = _profiles.setdefault(material, {})
    if key not in known:
        if len(known) >= 8:
            known.pop(next(iter(known)))
        known[key] = render_profile(material, variances)
    return known[key]


def render_params(scene: Scene, plan: Plan, *, medium=None, dtype=jnp.float32, radii=None) -> RenderParams:
    """Parameters of ``scene`` under ``plan``; ``medium`` replaces a homogeneous material's medium
    (pass a traced one to differentiate with respect to sigma_a, sigma_s' or eta). ``radii``
    [mm], where the render profile is fitted (default: from the scene's own profile), must
    be given when this runs under ``jit``."""
    if medium is None and radii is None:
        gs = _scene_profile(scene.material, plan.variances)
    else:
        gs = render_profile(scene.material, plan.variances, medium=medium, radii=radii)
    radiant = light_radiant(scene.lights, dtype)
    eta = scene.material.eta if medium is None else medium.eta
    eta = _in_dtype(np.broadcast_to(eta, (3,)), dtype) if is_concrete(eta) else jnp.broadcast_to(jnp.asarray(eta), (3,))
    weights, variances = _in_dtype(gs.weights, dtype), _in_dtype(gs.variances, dtype)
    total = weights.sum(0)
    if scene.material.normalize_profile:  # d'Eon 2007 sec. 5.3: the colour map alone sets the colour
        weights = weights / total
    medium = scene.material.medium if medium is None else medium
    if medium is not None and scene.material.kind == "medium":
        medium = jax.tree_util.tree_map(lambda a: _in_dtype(a, dtype), medium)
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
    exit_angle = medium if medium is not None and plan.on(Pass.EXIT_ANGLE) else None
    last_leg = medium if medium is not None and plan.on(Pass.LAST_LEG) else None
    first_leg = medium if medium is not None and plan.on(Pass.FIRST_LEG) else None
    return RenderParams(weights, variances, radiant, eta.astype(dtype), profile, medium, oblique,
                        deposit, map_params(scene, plan, total, dtype), exit_angle, last_leg, first_leg)


def _in_dtype(value, dtype) -> jax.Array:
    """``value`` as a ``dtype`` array; a concrete one is converted in NumPy (the same rounding),
    where JAX would compile a conversion per shape at every start."""
    if is_concrete(value):
        return device_array(np.asarray(value, jax.dtypes.canonicalize_dtype(dtype)))
    return jnp.asarray(value, dtype)


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


FRAME_PROGRAMS = 4  # prepared geometries whose frames are kept ready (with their arrays on the device)


class FrameProgram:
    """A compiled frame bound to one prepared geometry: ``program(params) -> radiance``.

    The program itself is shared by every prepared geometry of the same layout
    (:func:`jsss.render.programs.frame`: the geometry's arrays are its arguments, not its
    constants); this object holds the arrays, moved to the device once.
    """

    def __init__(self, method, prepared):
        self.layout, self._arrays = programs.split(prepared)
        self.program = programs.frame(method, self.layout)
        self._device: dict = {}  # x64 on or off -> the arrays as jnp (float64 becomes float32 when off)

    def arrays(self) -> tuple:
        """The geometry's arrays as the program reads them."""
        x64 = bool(jax.config.jax_enable_x64)
        if x64 not in self._device:
            self._device[x64] = tuple(device_array(np.asarray(a)) for a in self._arrays)
        return self._device[x64]

    def __call__(self, params: RenderParams):
        return self.program(params, self.arrays())

    def _cache_size(self) -> int:
        """Traces of the shared program (one per dtype of the parameters)."""
        return self.program._cache_size()


@functools.lru_cache(maxsize=FRAME_PROGRAMS)
def frame_program(method, prepared) -> FrameProgram:
    """The compiled frame ``params -> radiance`` of a method configuration and its prepared geometry.

    Kept for the last ``FRAME_PROGRAMS`` pairs: both compare by value (a configuration by its
    knobs, a prepared geometry by a digest of its data), so rendering a scene and plan again
    prepares them again (from the kept geometry, :mod:`jsss.render.memory`) but neither traces
    nor compiles. Another geometry of the same layout -- a light or the camera moved, another
    material -- runs the same compiled program (:mod:`jsss.render.programs`).
    """
    return FrameProgram(method, prepared)


def render(scene: Scene, plan: Plan | None = None, *, dtype=jnp.float32, time_passes: bool = False,
           repeats: int = 3) -> RenderResult:
    """Plan (unless given), prepare and render ``scene``.

    The frame runs as one jitted function, compiled once per method configuration and layout of
    the prepared geometry (:func:`frame_program`): a frame of the same scene again, or with
    other light intensities, another material, a light or the camera moved, does not
    recompile; the rasters, texels and shadow maps are kept while the mesh, the camera and the
    lights' positions stay (:mod:`jsss.render.memory`). For a loop over materials or light
    intensities, :func:`prepare_renderer` also skips planning and preparing.

    With ``time_passes`` every stage of the method is compiled (once, kept likewise) and timed,
    the median of ``repeats``; ``timings`` then holds the geometry's passes as this call
    prepared them (near 0 where the geometry was kept) and each JAX stage.
    """
    timings: dict = {}
    if plan is None:
        t0 = time.perf_counter()
        plan = plan_scene(scene)
        timings["plan"] = time.perf_counter() - t0
    method = plan.method_config
    params = render_params(scene, plan, dtype=dtype)
    prepared = method.prepare(scene, plan, params, timings=timings)
    frame = frame_program(method, prepared)
    if not time_passes:
        t0 = time.perf_counter()
        radiance = np.asarray(frame(params))
        timings["frame (with compile)"] = time.perf_counter() - t0
        return RenderResult(radiance, plan, timings, prepared)
    out = None
    for index, (name, _) in enumerate(method.stages(prepared)):
        out, timings[name] = _timed(programs.stage(method, frame.layout, index), params, out, frame.arrays(),
                                    repeats=repeats)
    return RenderResult(np.asarray(out), plan, timings, prepared)
