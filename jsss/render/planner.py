"""Decide how to render a scene -- which method, which passes, which knobs -- and say why.

**Method.** Four ways to produce subsurface light, from cheap to exact: ``lambert``
(total albedo, no spread), ``normal filtering`` (Patro 2007), ``image-space`` integration
(Mertens 2003) and ``texture-space`` diffusion (d'Eon 2007). The planner predicts each
one's error and time for the scene from the measured calibration table
(:mod:`.calibration`, written by ``benchmarks/methods.py --calibrate``) and takes the
cheapest that meets the accuracy target; ``method=`` overrides it. The plan carries it as an
immutable configuration with its knobs (``plan.method_config``, one of :mod:`jsss.render.methods`),
which :func:`jsss.render.render` runs.

**Texture-space passes** (when that method runs):

"Simulate only the effects a scene calls for" (DESIGN.md): every pass of the renderer is
switched on or off from measurable properties of the scene, and the knobs follow from its
accuracy target:

* **diffusion** -- off (Lambert with the profile's total albedo) when the profile's RMS
  radius is below the footprint of one pixel at the object's nearest point;
* **number of Gaussians** -- the fewest shared variances whose profile error (d'Eon's
  eq. 10, measured against the exact profile) meets the target;
* **texture size** -- the smallest power of two whose texel is no larger than that pixel
  footprint, capped by the scene's ``texture_size``;
* **blur steps** -- each step may at most double the variance when the target is below
  15 %, quadruple it (d'Eon's choice) otherwise: on a delta the doubling chain is within
  0.2 % of the analytic Gaussian, the quadrupling one 13-19 % (tests, benchmark);
* **stretch correction** -- off when the UV map's stretch varies by less than 10 %;
* **translucent shadow maps** -- off when no light crosses between opposite faces (normals
  more than 120 degrees apart), or when the thinnest such part (the thickness under which
  25 mm^2 of surface lies) passes less than a tenth of the target of the profile's light
  (:math:`e^{-d^2/2v}` weighting);
* **single scattering** -- Jensen's first-bounce term with its own angular law, for a
  homogeneous medium whose single-scattered light is at least a quarter of the target of the
  light leaving (:func:`single_scattering_share`); it takes that share from the diffusion
  light rather than adding to it (the dipole already holds every order);
* **oblique incidence** -- light arriving at a slant is deposited nearer the surface and more
  of it returns (Chandrasekhar's H function, :mod:`jsss.diffusion.incidence`); on for a homogeneous
  medium where light arriving at 60 degrees returns at least a quarter of the target more
  than the profiles' normal beam (ketchup's red: +14 %; marble: +1 %);
* **deposit depth** -- a point light's rays keep spreading below the surface, where light
  scatters (half a reduced mean free path deep, :func:`jsss.diffusion.incidence.deposit_depth`): on when
  reading the light there changes the irradiance under it by a quarter of the target
  (ketchup's lamp 35 mm above a 4 mm mean free path: 11 % in red);
* **layered profile** -- only for layered materials; **specular** -- when the material has one.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..diffusion.exit_law import lobe_change
from ..diffusion.incidence import deposit_depth, incidence_ratio, point_light_loss
from ..diffusion.lateral_step import first_leg_step, last_leg_step
from ..diffusion.single_scattering import single_scattering_share
from ..stored_programs import reusable_program
from .calibration import (
    METHODS,
    FrameFeatures,
    choose_method,
    estimate_methods,
    knob_label,
    load_calibration,
    parse_knob,
)
from .environment import SCATTERING_CELLS, VISIBILITY_DIRECTIONS
from .lighting import light_geometry, shadow_map
from .mesh import distance_to_surface, is_closed, shadows_itself
from .methods import (
    CONFIGURATIONS,
    ImageSpace,
    NormalFiltering,
    RenderMethod,
    TextureSpace,
)
from .passes import Method, Pass
from .profile_blend import ProfileBasis, choose_basis
from .profile_choice import ProfileChoice, choose_profile, map_media
from .profiles import choose_variances, full_profile, render_profile
from .scene import Scene
from .texture_space import bake_texels, face_stretch, stretch_variation

__all__ = ["PassDecision", "Plan", "deposit_change", "frame_features", "method_config", "plan_scene"]

STRETCH_THRESHOLD = 0.10
PASS_ORDER = tuple(Pass)
TEXTURE_KNOBS = (0.2, 0.05, 0.01)  # profile targets the calibration renders texture space with
SAMPLE_KNOBS = (8, 32, 128)  # samples per pixel the calibration renders image space with


@dataclass(frozen=True)
class PassDecision:
    name: str
    on: bool
    why: str


@dataclass(frozen=True, eq=False)
class Plan:
    """The method, the passes to run, their knobs and the reasons.

    Attributes
    ----------
    decisions : tuple of PassDecision, in pass order
    variances : ndarray (n,) [mm^2], the shared Gaussian variances of the render profile
        (every method's parameters are fitted on them; texture space blurs to each)
    profile_error : float, relative RMS error of that profile (worst channel)
    method_config : RenderMethod, the method and its knobs (:mod:`jsss.render.methods`):
        ``Lambert()``, ``NormalFiltering(kind)``, ``ImageSpace(samples)`` or
        ``TextureSpace(size, taps, max_ratio)``
    pixel_size : float [mm] footprint of a pixel at the object's nearest point
    method_why : str; estimates : tuple of MethodEstimate (empty when the method was given)
    blur_pixels : float, the profile's RMS radius over the pixel footprint
    knob : str, the chosen knob as the calibration table labels it (``"32 spp"``, ...)
    features : FrameFeatures, what the method's predicted error rests on (:func:`frame_features`)
    basis : ProfileBasis or None, the basis profiles a material's parameter maps are blended
        from (:mod:`jsss.render.profile_blend`); ``variances`` are then the basis'
    profile : ProfileChoice or None, a homogeneous medium's profile model (dipole or
        transport), why, and both models' predicted errors against the transport truth
        (:mod:`jsss.render.profile_choice`); None for a stack or a given profile

    ``method`` (the :class:`~jsss.render.passes.Method`) and the knobs ``texture_size``,
    ``taps``, ``max_ratio``, ``samples`` and ``normal_filter`` read the configuration (None
    where the method has no such knob).
    """

    decisions: tuple
    variances: np.ndarray
    profile_error: float
    method_config: RenderMethod
    pixel_size: float
    method_why: str = ""
    estimates: tuple = ()
    blur_pixels: float = 0.0
    knob: str = ""
    features: FrameFeatures | None = None
    basis: ProfileBasis | None = None
    profile: ProfileChoice | None = None

    @property
    def method(self) -> Method:
        return self.method_config.method

    @property
    def texture_size(self) -> int | None:
        return self.method_config.size if isinstance(self.method_config, TextureSpace) else None

    @property
    def taps(self) -> int | None:
        return self.method_config.taps if isinstance(self.method_config, TextureSpace) else None

    @property
    def max_ratio(self) -> float | None:
        return self.method_config.max_ratio if isinstance(self.method_config, TextureSpace) else None

    @property
    def samples(self) -> int | None:
        return self.method_config.samples if isinstance(self.method_config, ImageSpace) else None

    @property
    def normal_filter(self) -> str | None:
        return self.method_config.kind if isinstance(self.method_config, NormalFiltering) else None

    def on(self, name: Pass) -> bool:
        for d in self.decisions:
            if d.name == name:
                return d.on
        raise KeyError(f"no pass named {name!r}; passes: {', '.join(PASS_ORDER)}.")

    def replace(self, name: str, on: bool, why: str) -> Plan:
        decisions = tuple(PassDecision(d.name, on, why) if d.name == name else d for d in self.decisions)
        return dataclasses.replace(self, decisions=decisions)

    def describe(self) -> str:
        head = [f"method: {self.method} -- {self.method_why}",
                f"  profile RMS radius spans {self.blur_pixels:.3g} pixels"]
        if self.profile is not None:
            head.insert(1, f"  {self.profile.describe()}")
        if self.features is not None:
            head.append(f"  frame: {self.features.describe()}")
        if self.estimates:
            head.append("  predicted for this scene (from the calibration table):")
            head.append(f"    {'method':<18} {'knob':<12} {'error':>8} {'ms':>9}  basis")
            for e in self.estimates:
                mark = "*" if (e.method, e.knob) == (self.method, self.knob) else " "
                head.append(f"  {mark} {e.method:<18} {e.knob:<12} {100 * e.error:7.2f}% {e.ms:9.3g}  {e.basis}")
        width = max(len(d.name) for d in self.decisions)
        lines = [f"  {'on ' if d.on else 'off'}  {d.name:<{width}}  {d.why}" for d in self.decisions]
        return "\n".join(head + ["plan:"] + lines + [f"  knobs: {self.method_config.describe(self)}"])


def method_config(method: Method | str, *, texture_size: int = 512, taps: int = 7, max_ratio: float = 4.0,
                  samples: int = 32, normal_filter: str = "spectral") -> RenderMethod:
    """The configuration of ``method`` with those of the knobs it has (the others are not read).

    Raises ``ValueError`` for an unknown method, or a knob the configuration refuses.
    """
    method = Method(method)
    knobs = {Method.LAMBERT: {}, Method.NORMAL_FILTERING: {"kind": normal_filter},
             Method.IMAGE_SPACE: {"samples": samples},
             Method.TEXTURE_SPACE: {"size": texture_size, "taps": taps, "max_ratio": max_ratio}}[method]
    return CONFIGURATIONS[method](**knobs)


def _pixel_footprint(scene: Scene) -> float:
    lo, hi = scene.mesh.bounds
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    nearest = max(np.linalg.norm(np.asarray(scene.camera.position) - center) - radius, 1e-3)
    return float(scene.camera.pixel_size(nearest))


def frame_features(scene: Scene) -> FrameFeatures:
    """The features a method's error is predicted from (:class:`jsss.render.calibration.FrameFeatures`).

    ``backlit`` weighs each light by the irradiance it brings to the object's centre (a
    directional light its intensity, a point light intensity / distance^2, times its mean
    colour; an environment each direction's radiance times its solid angle) and counts those
    travelling towards the camera (their direction against the camera's view axis); ``curvature`` is the profile's RMS radius over half the bounding
    box's smallest side of a closed object, 0 for an open one.
    """
    lo, hi = (np.asarray(b, float) for b in scene.mesh.bounds)
    center = (lo + hi) / 2
    rms = _profile_rms(scene.material)
    pixel = _pixel_footprint(scene)
    view = np.asarray(scene.camera.look_at, float) - np.asarray(scene.camera.position, float)
    view /= np.linalg.norm(view)
    behind = total = 0.0
    for light in scene.lights:
        if light.kind == "environment":  # each direction weighed by the radiance arriving from it
            beyond, power = light.incoming_power(view)
            total, behind = total + power, behind + beyond
            continue
        power = float(light.intensity * np.mean(light.color))
        if light.kind == "directional":
            travel = np.asarray(light.direction, float)
        else:
            travel = center - np.asarray(light.position, float)
            power /= max(float(travel @ travel), 1e-12)
        travel = travel / max(np.linalg.norm(travel), 1e-12)
        total += power
        behind += power if travel @ view < 0 else 0.0
    closed = is_closed(scene.mesh)
    curvature = rms / max(float(np.min(hi - lo)) / 2, 1e-9) if closed else 0.0
    return FrameFeatures(blur_pixels=rms / pixel, blur_frame=rms / (pixel * scene.camera.height), closed=closed,
                         backlit=behind / total if total > 0 else 0.0, curvature=float(curvature))


class ScaleWarning(UserWarning):
    """The material's profile and the object differ so much in size that the scene's unit is
    likely not millimetres."""


def _check_units(scene: Scene, rms: float) -> None:
    """Warn (:class:`ScaleWarning`) where the profile's RMS radius ``rms`` [mm] exceeds the
    object's size: a scene written in metres (a marble ball of radius 0.02) plans a profile
    27000 pixels wide and renders as a flat wash. jsss's unit is the millimetre."""
    lo, hi = (np.asarray(b, float) for b in scene.mesh.bounds)
    size = float(np.max(hi - lo))
    if rms > size:
        warnings.warn(f"{scene.source}: the material's light spreads {rms:.3g} mm (RMS radius) across an object "
                      f"{size:.3g} mm wide: lengths in a scene are millimetres and coefficients 1/mm (a scene in "
                      "metres: [geometry] scale = 1000 and its camera and light positions in mm)",
                      ScaleWarning, stacklevel=3)


def _irradiance_why(scene: Scene, *, single_scattering: bool) -> str:
    lights = [light for light in scene.lights if light.kind != "environment"]
    parts = [f"{len(lights)} light(s) with Fresnel transmittance"] if lights else []
    for env in (light for light in scene.lights if light.kind == "environment"):
        part = (f"an environment ({env.source}) as a map of irradiance per normal, prefiltered with the Fresnel "
                "transmittance (and the oblique law where it runs)")
        if scene.material.specular > 0:
            part += "; its reflection as the map blurred by the specular lobe"
        if single_scattering:
            part += f"; its single scattering from {np.prod(SCATTERING_CELLS)} cells of the map"
        parts.append(part)
    return "; ".join(parts)


def _shadows_why(scene: Scene) -> str:
    parts = ["shadow map per light"] if any(light.kind != "environment" for light in scene.lights) else []
    if any(light.kind == "environment" for light in scene.lights):
        if shadows_itself(scene.mesh):
            parts.append(f"the environment: {VISIBILITY_DIRECTIONS} directional shadow maps, since the closed "
                         "surface falls short of its convex hull and can hide the sky from itself")
        else:
            parts.append("the environment: none, since the surface is convex or open and sees its whole upper "
                         "hemisphere")
    return "; ".join(parts)


def _uv_unit_length(scene: Scene) -> float:
    """Median world length [mm] of one unit of UV (area-weighted over faces and both axes)."""
    du, dv, _ = face_stretch(scene.mesh)
    lengths = np.concatenate([du, dv])
    return float(np.median(lengths[lengths > 0]))


def _profile_rms(material) -> float:
    """RMS radius [mm] of the material's whole profile (widest channel): sqrt(sum 2 v w / sum w)."""
    full = full_profile(material)
    v, w = np.asarray(full.variances), np.abs(np.asarray(full.weights))
    return float(np.max(np.sqrt((2 * v[:, None] * w).sum(0) / np.maximum(w.sum(0), 1e-300))))


def plan_scene(scene: Scene, *, accuracy: float | None = None, method: Method | str | None = None,
               samples: int | None = None, normal_filter: str = "spectral", calibration=None) -> Plan:
    """The plan for ``scene`` (its own accuracy target unless ``accuracy`` is given).

    Parameters
    ----------
    scene : Scene
    accuracy : float in (0, 1), optional
        Relative RMS error the frame may have.
    method : str, optional
        One of ``lambert``, ``normal filtering``, ``image-space``, ``texture-space``; default:
        the scene's ``[render] method`` where it names one, else the cheapest predicted to meet
        ``accuracy`` by the calibration table.
    samples : int, optional
        Image-space samples per pixel (default: the calibration's choice, else 32).
    normal_filter : {"spectral", "naive"}
        Which Patro filter a given ``method="normal filtering"`` uses.
    calibration : path, optional
        Another calibration table (default: the one shipped with jsss).
    """
    target = scene.accuracy if accuracy is None else accuracy
    if not 0 < target < 1:
        raise ValueError(f"accuracy must lie in (0, 1) (a relative error); got {target}.")
    set_by = "the caller (--method)"
    if method is None and scene.method is not None:
        method, set_by = scene.method, "the scene ([render] method)"
    if method is not None:
        try:
            method = Method(method)
        except ValueError:
            raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}.") from None
    if normal_filter not in ("spectral", "naive"):
        raise ValueError(f"normal_filter must be 'spectral' or 'naive'; got {normal_filter!r}.")
    if samples is not None and samples < 1:
        raise ValueError(f"samples must be >= 1 per pixel; got {samples}.")
    material = scene.material
    if method == Method.TEXTURE_SPACE and not scene.mesh.has_uvs:
        raise ValueError(f"{scene.source}: texture-space needs the mesh's UV layout, and {scene.mesh.name} has "
                         "none (no vt lines); use lambert, normal-filtering or image-space.")
    pixel = _pixel_footprint(scene)
    features = frame_features(scene)
    blur = features.blur_pixels
    rms = blur * pixel
    _check_units(scene, rms)
    unit = _uv_unit_length(scene) if scene.mesh.has_uvs else pixel  # a texel no larger than the pixel footprint
    size = 64
    while size < scene.texture_size and unit / size > pixel:
        size *= 2
    size = min(size, scene.texture_size)
    pixels = scene.camera.width * scene.camera.height
    work = {m: pixels for m in METHODS} | {Method.TEXTURE_SPACE: size * size}
    estimates: tuple = ()
    maps = material.maps
    basis = None
    if maps is not None and maps.parametric:
        # Half the profile's budget to the Gaussians, half to blending between the basis profiles.
        basis = choose_basis(material, maps.sigma_a, maps.sigma_s_prime, target / 4)
    if method is None:
        estimates = tuple(estimate_methods(load_calibration(calibration), features, work))
        if not scene.mesh.has_uvs:  # no UV layout to diffuse in
            estimates = tuple(e for e in estimates if e.method != Method.TEXTURE_SPACE)
        if maps is not None:
            estimates = _with_maps(estimates, map_spread_error(scene, rms), basis)
        chosen, method_why = choose_method(estimates, target)
        method = chosen.method
        knobs = parse_knob(method, chosen.knob)
        samples = knobs.get("samples", samples)
        normal_filter = knobs.get("normal_filter", normal_filter)
        texture_target = knobs.get("target", target)
        knob = chosen.knob
    else:
        method_why = f"set by {set_by}"
        texture_target = target
        knob = None
    samples = 32 if samples is None else samples
    if knob is None:
        knob = knob_label(method, samples=samples, normal_filter=normal_filter, target=texture_target)

    decisions = {Pass.SHADOWS: (True, _shadows_why(scene)),
                 Pass.CAMERA: (True, "rasterize, look up, tone map")}
    if basis is not None:
        variances = basis.variances
        w = np.asarray(render_profile(material, variances).weights, float)
        error = basis.fit_error + basis.error
        reached = basis.fit_error <= target / 4 and basis.error <= target / 4
    else:
        gs, error, reached = choose_variances(material, texture_target / 2, resolution=pixel)
        variances, w = np.asarray(gs.variances), np.asarray(gs.weights)
    decisions[Pass.SURFACE_MAPS] = _maps_decision(material, basis, method)
    total = w.sum(0)
    if material.layers:
        decisions[Pass.LAYERED_PROFILE] = (True, f"{len(material.layers)} layers"
                                              + (" on a base" if material.base is not None else ""))
    else:
        decisions[Pass.LAYERED_PROFILE] = (False, f"material is {material.kind}, not layered")
    texture = method == Method.TEXTURE_SPACE
    diffusion = texture and rms >= pixel
    spread = f"profile RMS radius {rms:.3g} mm {'>=' if rms >= pixel else '<'} pixel footprint {pixel:.3g} mm"
    albedo = "/".join(f"{t:.3f}" for t in total)
    decisions[Pass.DIFFUSION] = (diffusion, {
        Method.TEXTURE_SPACE: spread + ("" if diffusion else "; Lambert with the total albedo " + albedo),
        Method.LAMBERT: f"Lambert with the total albedo {albedo} ({spread})",
        Method.NORMAL_FILTERING: "normal filtering stands in for it",
        Method.IMAGE_SPACE: "image-space integration stands in for it"}[method])
    decisions[Pass.NORMAL_FILTERING] = (method == Method.NORMAL_FILTERING, (
        f"{normal_filter} filter of the normals per channel, gain = the profile's Hankel transform "
        f"(falls to 1/2 near {1 / rms:.3g} rad/mm)") if method == Method.NORMAL_FILTERING else f"method is {method}")
    decisions[Pass.IMAGE_SPACE_INTEGRATION] = (method == Method.IMAGE_SPACE, (
        f"{samples} samples per pixel drawn from the profile, 1/4 uniform on a disc, balance heuristic")
        if method == Method.IMAGE_SPACE else f"method is {method}")
    if texture:
        decisions[Pass.TEXTURE_GEOMETRY] = (True, "positions, normals and stretch per texel (once per mesh)")
        variation = stretch_variation(scene.mesh)
        stretch = diffusion and variation >= STRETCH_THRESHOLD
        decisions[Pass.STRETCH_CORRECTION] = (stretch, f"UV stretch varies by {100 * variation:.0f} % "
                                                    f"({'>=' if variation >= STRETCH_THRESHOLD else '<'} "
                                                    f"{100 * STRETCH_THRESHOLD:.0f} %)"
                                           + ("" if diffusion else "; no diffusion to correct"))
        decisions[Pass.TRANSLUCENT_SHADOW_MAPS] = _tsm_decision(scene, variances, w, texture_target)
    else:
        for name in (Pass.TEXTURE_GEOMETRY, Pass.STRETCH_CORRECTION, Pass.TRANSLUCENT_SHADOW_MAPS):
            decisions[name] = (False, f"texture space only; method is {method}")
    nodes = None if basis is None else basis.media(material.eta)  # parameter maps: every node's medium counts
    decisions[Pass.SINGLE_SCATTERING] = _single_scattering_decision(material, target, nodes)
    decisions[Pass.IRRADIANCE] = (True, _irradiance_why(scene, single_scattering=decisions[Pass.SINGLE_SCATTERING][0]))
    decisions[Pass.OBLIQUE_INCIDENCE] = oblique_incidence_decision(material, target, nodes)
    decisions[Pass.EXIT_ANGLE] = exit_angle_decision(material, target, nodes,
                                                     first_bounce_apart=decisions[Pass.SINGLE_SCATTERING][0])
    decisions[Pass.DEPOSIT_DEPTH] = deposit_depth_decision(scene, target, nodes)
    decisions[Pass.FIRST_LEG] = first_leg_decision(scene, target, nodes, method=method)
    decisions[Pass.LAST_LEG] = last_leg_decision(scene, target, nodes, method=method)
    spec = material.specular > 0
    decisions[Pass.SPECULAR] = (spec, f"Beckmann m = {material.roughness:g}, weight {material.specular:g}"
                             if spec else "material specular = 0")
    if not reached:
        profile_pass = Pass.LAYERED_PROFILE if material.layers else Pass.DIFFUSION
        on, why = decisions[profile_pass]
        decisions[profile_pass] = (on, why + " (target not reachable with 12 Gaussians; best shown)")
    ordered = tuple(PassDecision(name, *decisions[name]) for name in PASS_ORDER)
    config = method_config(method, texture_size=size, taps=7, max_ratio=2.0 if texture_target < 0.15 else 4.0,
                           samples=samples, normal_filter=normal_filter)
    return Plan(ordered, variances, error, config, pixel, method_why=method_why, estimates=estimates, blur_pixels=blur,
                knob=knob, features=features, basis=basis, profile=_profile_at(material, target))


def _profile_at(material, target):
    """The material's profile choice, flagged where ``auto`` chose for another target than this
    plan's (``plan_scene(accuracy=...)``, ``--accuracy``): the material, and so the frame, keeps
    its model; the plan says so and which model this target would take."""
    choice = material.profile
    if choice is None or choice.requested != "auto" or np.isclose(choice.target, target):
        return choice
    other = choose_profile(material.medium, g=material.g, target=target, texels=map_media(material.maps, material.eta))
    if other.model == choice.model:
        return choice
    note = (f" [chosen for accuracy {100 * choice.target:.3g} %; at this plan's {100 * target:.3g} % auto would take "
            f"{other.model}: set [render] accuracy, or profile]")
    warnings.warn(f"profile: {choice.model} was chosen for accuracy {100 * choice.target:.3g} %, and this plan's "
                  f"{100 * target:.3g} % would take {other.model}; set the scene's accuracy (or its profile) to change it",
                  stacklevel=3)
    return dataclasses.replace(choice, why=choice.why + note)


def map_spread_error(scene: Scene, rms: float) -> float:
    """Relative RMS error, over the map, of a method that applies the maps at one point (Lambert,
    normal filtering) where the light spreads by the profile's RMS radius ``rms`` [mm].

    Each map's reflectance -- the colour map under its texturing rule, and each texel's dipole
    total where the parameters vary -- is blurred in UV by a Gaussian of that radius (per axis
    rms / sqrt 2, in texels of the mesh's median UV scale): the exitance is then
    ``exit * blur(entry * reflectance)``, against ``exit * entry * reflectance`` unspread. The
    two maps' errors add.
    """
    from ..diffusion import dipole
    from ..medium import Medium

    maps = scene.material.maps
    error = 0.0
    if maps.parametric:
        total = dipole.total_reflectance(Medium(maps.sigma_a, maps.sigma_s_prime, np.asarray(scene.material.eta)))
        total = np.asarray(total, float)
        error += _spread(total, np.ones_like(total), scene, rms)
    if maps.colour is not None:
        c = maps.colour
        entry, exit_ = {"pre-post": (np.sqrt(c), np.sqrt(c)), "pre": (c, np.ones_like(c)),
                        "post": (np.ones_like(c), c)}[maps.texturing]
        error += _spread(entry, exit_, scene, rms)
    return error


def _spread(source, exit_, scene: Scene, rms: float) -> float:
    from scipy.ndimage import gaussian_filter

    unit = _uv_unit_length(scene)
    height, width = source.shape[:2]
    sigma = (rms / np.sqrt(2) / (unit / height), rms / np.sqrt(2) / (unit / width), 0)
    mode = ("nearest", "wrap" if scene.mesh.wrap_u else "nearest", "nearest")
    spread = exit_ * gaussian_filter(source, sigma, mode=mode)
    return float(np.sqrt(np.mean((exit_ * source - spread) ** 2) / max(np.mean(spread**2), 1e-300)))


def _with_maps(estimates, spread_error, basis):
    """The calibration's estimates for a textured material: the methods that apply the maps at
    one point add the map's own spread error; texture space blurs once per basis profile
    (its frame time grows about that many times: 3.9x for 4, 5.3x for 6 in
    benchmarks/textured.py)."""
    out = []
    for e in estimates:
        if e.method in (Method.LAMBERT, Method.NORMAL_FILTERING):
            e = dataclasses.replace(e, error=e.error + spread_error,
                                    basis=e.basis + f"; + {100 * spread_error:.2g} % unspread maps")
        elif e.method == Method.TEXTURE_SPACE and basis is not None and basis.size > 1:
            e = dataclasses.replace(e, ms=e.ms * basis.size, basis=e.basis + f"; x {basis.size} basis profiles")
        out.append(e)
    return tuple(out)


def _maps_decision(material, basis, method):
    """Whether the material varies over the surface, how, and what it costs."""
    maps = material.maps
    if maps is None:
        return False, "homogeneous material (no [material.maps])"
    why = maps.describe()
    if basis is not None:
        extra = {Method.TEXTURE_SPACE: f"the diffusion blurs {basis.size}x the channels",
                 Method.IMAGE_SPACE: f"each sample evaluates {basis.size} profiles at its entry point",
                 Method.LAMBERT: "the total albedo per pixel", Method.NORMAL_FILTERING:
                 "the total albedo per pixel; normals filtered with the material's own profile"}[method]
        why += f"; {basis.describe()}; {extra}"
    if material.normalize_profile:
        why += "; profile normalised to white (the colour map sets the colour)"
    return True, why


TSM_TEXELS = 64         # texels per side the translucent-shadow-map decision looks at (its map: 4x finer)
THIN_PART_AREA = 25.0  # mm^2 of surface that must lie behind a thin part for it to count


def _tsm_decision(scene: Scene, variances, weights, target):
    """Thinnest part that light cuts through, from one face to an opposite one.

    Where light enters on a face turned the same way as the shadowed point (any shadowed
    point near the terminator of a convex body) the texture-space blur already carries
    that light around the surface; translucent shadow maps add light that crosses from a
    face to one turned away from it (normals more than 120 degrees apart): an ear, a fin,
    the far side of a ball.
    """
    texels = bake_texels(scene.mesh, TSM_TEXELS)
    thinnest = np.inf
    for light in scene.lights:
        if light.kind == "environment":  # translucent shadow maps follow one direction
            continue
        shadow = shadow_map(scene.mesh, light, size=4 * TSM_TEXELS)
        g = light_geometry(texels.position, texels.normal, texels.mask, light, shadow)
        index = np.clip((g.front_uv * texels.size).astype(int), 0, texels.size - 1)
        front_normal = texels.normal[index[..., 1], index[..., 0]]
        through = (g.behind > 0) & ((front_normal * texels.normal).sum(-1) < -0.5)
        if through.any():
            # The thickness under which THIN_PART_AREA of such surface lies: a part the size of an
            # ear lobe counts however large the rest of the shadowed side (a percentile of the
            # texels did not: the head's ears are 0.1 % of what its far side holds under the
            # example's rim light, and their glow, up to +82 % in red, went unplanned).
            order = np.argsort(g.thickness[through])
            area = np.cumsum(texels.area[through][order])
            k = min(int(np.searchsorted(area, THIN_PART_AREA)), len(order) - 1)
            thinnest = min(thinnest, float(g.thickness[through][order][k]))
    if not np.isfinite(thinnest):
        return False, "no light crosses between opposite faces"
    w = np.abs(weights)
    share = float(np.max((w * np.exp(-thinnest**2 / (2 * variances))[:, None]).sum(0) / np.maximum(w.sum(0), 1e-300)))
    on = share >= 0.1 * target
    return on, (f"thinnest part light cuts through: {thinnest:.3g} mm, passing {share:.2e} of the profile's light "
                f"({'>=' if on else '<'} {0.1 * target:.2g})")


OBLIQUE_COSINE = 0.5  # light arriving 60 degrees from the normal: where the planner weighs the effect


def _largest(values) -> np.ndarray:
    """(3,): per channel, the value of largest magnitude over the media (rows of (..., 3))."""
    values = np.asarray(values, float).reshape(-1, 3)
    return values[np.argmax(np.abs(values), 0), np.arange(3)]


def oblique_incidence_decision(material, target, nodes=None):
    """On when light arriving at 60 degrees returns at least a quarter of the target more (or
    less) than a normal beam, in some channel (:func:`jsss.diffusion.incidence.incidence_ratio`)
    of the material's medium or of any basis node's (``nodes``, a Medium (K, 3), parameter maps)."""
    if material.medium is None:
        return False, f"needs a homogeneous medium; material is {material.kind}"
    media = [material.medium] + ([] if nodes is None else [nodes])
    growth = _largest(np.concatenate([np.asarray(incidence_ratio(m, OBLIQUE_COSINE), float).reshape(-1, 3)
                                      for m in media]) - 1)
    on = bool(np.abs(growth).max() >= target / 4)
    shown = "/".join(f"{100 * x:+.1f}" for x in growth * np.ones(3))
    return on, (f"light arriving at 60 degrees returns {shown} % more than a normal beam "
                f"({'>=' if on else '<'} a quarter of the target, {100 * target / 4:.2g} %); the profiles are for "
                "normal incidence, so the irradiance is scaled by Chandrasekhar's law")


def exit_angle_decision(material, target, nodes=None, *, first_bounce_apart: bool):
    """On when the light of the material's medium leaves, toward some view, at least a quarter of
    the target off the flat diffusion lobe (:func:`jsss.diffusion.exit_law.lobe_change`: along the
    normal, at 60 or at 78 degrees, under a normal beam or uniform light); of the multiply
    scattered light alone when single scattering runs apart (``first_bounce_apart``). Off for
    parameter maps (``nodes``): the law is one medium's."""
    if material.medium is None:
        return False, f"needs a homogeneous medium; material is {material.kind}"
    if nodes is not None:
        return False, "parameter maps: the exit law is one medium's; the flat diffusion lobe is used"
    change = lobe_change(material.medium, first_bounce_apart=first_bounce_apart) * np.ones(3)
    on = bool(np.abs(change).max() >= target / 4)
    shown = "/".join(f"{100 * x:+.1f}" for x in change)
    light = "multiply scattered light" if first_bounce_apart else "light"
    return on, (f"the {light} leaves up to {shown} % off the flat diffusion lobe toward some view "
                f"({'>=' if on else '<'} a quarter of the target, {100 * target / 4:.2g} %)"
                + ("; spread by Chandrasekhar's kernel of the light that arrives" if on else ""))


def deposit_change(scene, nodes=None):
    """(change, nearest, depth): how much less irradiance reaches the deposit depth ``depth``
    [mm, deepest channel of the medium and of any basis node ``nodes``] than the surface, under
    the nearest point light (``nearest`` mm from the mesh); (0, inf, depth) without point lights
    or a homogeneous medium."""
    material = scene.material
    nearest = _nearest_point_light(scene)
    if material.medium is None or np.isinf(nearest):
        return 0.0, np.inf, 0.0
    loss, depth = (float(x) for x in _under_a_lamp(material.medium, nodes, nearest)[:2])
    return loss, nearest, depth


def deposit_depth_decision(scene, target, nodes=None):
    """On when a point light is near enough that reading it at the deposit depth changes its
    irradiance under the lamp by a quarter of the target (:func:`jsss.diffusion.incidence.deposit_depth`),
    at the deepest of the medium's and the basis nodes' (``nodes``) depths."""
    material = scene.material
    if material.medium is None:
        return False, f"needs a homogeneous medium; material is {material.kind}"
    change, nearest, depth = deposit_change(scene, nodes)
    if np.isinf(nearest):
        return False, "no point light (parallel rays do not spread below the surface)"
    on = bool(change >= target / 4)
    return on, (f"a point light {nearest:.0f} mm away, read {depth:.2f} mm deep where light scatters: "
                f"{100 * change:.1f} % less under the lamp ({'>=' if on else '<'} a quarter of the target, "
                f"{100 * target / 4:.2g} %)")


LAST_LEG_VIEW_COSINE = 0.5   # the camera 60 degrees off the normal: where the planner weighs the last leg


FIRST_LEG_LIGHT_COSINE = 0.5  # light 60 degrees off the normal: where the planner weighs the first leg


def last_leg_change(scene):
    """(change, step, nearest): how much the exitance changes over the last leg's mean step
    ``step`` [mm, every order's, the longest channel's, viewed at 60 degrees under a normal beam:
    :func:`jsss.diffusion.lateral_step.last_leg_step`], under the nearest point light (``nearest``
    mm from the mesh) or at an open surface's rim (:func:`_leg_change`). (0, 0, inf) on a closed
    surface without point lights or without a homogeneous medium (the step is not computed: it
    would be a JAX program at every start)."""
    return _leg_change(scene, last=True)


def first_leg_change(scene):
    """(change, step, nearest) of the light's first leg (:mod:`jsss.render.first_leg`), as
    :func:`last_leg_change`: its mean step for light 60 degrees off the normal that leaves along
    it (:func:`jsss.diffusion.lateral_step.first_leg_step`), at an open surface's rim under a
    directional light (the pass moves parallel light only); ``nearest`` is inf."""
    return _leg_change(scene, last=False)


def _leg_change(scene, *, last: bool):
    """Under a lamp at height h the irradiance falls by at most 3/(2h) per mm (at a distance h
    from the foot): change = 1.5 step / nearest. At an open surface's rim the exitance falls
    to about half over a diffusion length :math:`1/\\sigma_{tr}`: change = :math:`\\sigma_{tr}`
    step, the largest channel's. The larger of the two."""
    nearest = _nearest_point_light(scene) if last else np.inf
    rim = not is_closed(scene.mesh) and (last or any(light.kind == "directional" for light in scene.lights))
    if scene.material.medium is None or (np.isinf(nearest) and not rim):
        return 0.0, 0.0, np.inf
    numbers = _under_a_lamp(scene.material.medium, None, nearest)
    step, at_rim = (float(numbers[2]), float(numbers[3])) if last else (float(numbers[4]), float(numbers[5]))
    change = max(1.5 * step / nearest, at_rim if rim else 0.0)
    return change, step, nearest


@reusable_program()
@jax.jit
def _under_a_lamp(medium, nodes, nearest):
    """(irradiance lost at the deposit depth, that depth [mm], the last leg's step [mm], its change
    at a rim, the first leg's step [mm], its change at a rim) under a point light ``nearest`` mm
    away: the deepest and longest channel of ``medium`` (and of the basis nodes' media ``nodes``,
    or None). One program kept across processes, not 45 eager operations each compiled at a
    start (0.4 s of the ketchup plane's)."""
    depth = jnp.max(deposit_depth(medium))
    if nodes is not None:
        depth = jnp.maximum(depth, jnp.max(deposit_depth(nodes)))
    sigma_a, sigma_s = jnp.asarray(medium.sigma_a), jnp.asarray(medium.sigma_s_prime)
    sigma_tr = jnp.sqrt(3 * sigma_a * (sigma_a + sigma_s))
    last = last_leg_step(medium, 1.0, LAST_LEG_VIEW_COSINE)
    first = first_leg_step(medium, FIRST_LEG_LIGHT_COSINE, 1.0)
    return (point_light_loss(nearest, depth), depth, jnp.max(last), jnp.max(sigma_tr * last), jnp.max(first),
            jnp.max(sigma_tr * first))


def _nearest_point_light(scene) -> float:
    """Distance [mm] from the mesh to its nearest point light; inf without point lights."""
    points = [light for light in scene.lights if light.kind == "point"]
    return min((distance_to_surface(scene.mesh, light.position) for light in points), default=np.inf)


def _leg_decision(scene, target, nodes, method, *, last: bool):
    material = scene.material
    if material.medium is None:
        return False, f"needs a homogeneous medium; material is {material.kind}"
    if nodes is not None:
        return False, f"parameter maps: the {'last' if last else 'first'} leg's step is one medium's; read at the pixel"
    change, step, nearest = _leg_change(scene, last=last)
    if step == 0.0:
        return False, ("no point light and no open rim: the light changes slowly over a transport mean free path"
                       if last else "no open rim under a directional light (a point light's steps fan out: the "
                       "pass moves parallel light only)")
    on = bool(change >= target / 4)
    where = f"under a lamp {nearest:.0f} mm away" if np.isfinite(nearest) else "at the open surface's rim"
    if np.isfinite(nearest) and not is_closed(scene.mesh):
        where += " or at the open surface's rim"
    moved = ("the light seen was last scattered up to {:.2g} mm farther from the eye" if last
             else "oblique light is first scattered up to {:.2g} mm farther along its way").format(step)
    why = (f"{moved}; {where} that changes it by up to {100 * change:.1f} % "
           f"({'>=' if on else '<'} a quarter of the target, {100 * target / 4:.2g} %)")
    if on and method is not None and method != Method.TEXTURE_SPACE:
        return False, why + f"; texture space only, method is {method}"
    return on, why + ("; each channel is read there" if on else "")


def last_leg_decision(scene, target, nodes=None, *, method=None):
    """On when the exitance under the nearest point light, or at an open surface's rim, changes
    over the last leg's mean step by a quarter of the target (:func:`last_leg_change`); texture
    space runs it (``method`` None: the physics alone, as the reference asks). Off for parameter
    maps: the step is one medium's."""
    return _leg_decision(scene, target, nodes, method, last=True)


def first_leg_decision(scene, target, nodes=None, *, method=None):
    """On when the exitance at an open surface's rim under a directional light changes over the
    first leg's mean step by a quarter of the target (:func:`first_leg_change`); texture space
    runs it (``method`` None: the physics alone, as the reference asks)."""
    return _leg_decision(scene, target, nodes, method, last=False)


def _single_scattering_decision(material, target, nodes=None):
    if material.medium is None:
        return False, f"needs a homogeneous medium; material is {material.kind}"
    share = single_scattering_share(material.medium) * np.ones(3)
    if nodes is not None:  # the largest share of any basis node's medium
        share = np.maximum(share, np.asarray(single_scattering_share(nodes), float).reshape(-1, 3).max(0))
    on = bool(share.max() >= target / 4)
    shares = "/".join(f"{100 * s:.1f}" for s in share)
    return on, (f"first bounce carries {shares} % of the light leaving "
                f"({'>=' if on else '<'} a quarter of the target, {100 * target / 4:.2g} %); "
                "it replaces that share of the diffusion light")
