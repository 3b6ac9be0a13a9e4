"""Decide which passes a scene needs and with which knobs, and say why.

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
  more than 120 degrees apart), or when the thinnest such part passes
  less than a tenth of the target of the profile's light (:math:`e^{-d^2/2v}` weighting);
* **layered profile** -- only for layered materials; **specular** -- when the material has one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .lighting import light_geometry, shadow_map
from .profiles import choose_variances
from .scene import Scene
from .texture_space import bake_texels, face_stretch, stretch_variation

__all__ = ["PassDecision", "Plan", "plan_scene"]

STRETCH_THRESHOLD = 0.10
PASS_ORDER = ("texture geometry", "irradiance", "shadows", "layered profile", "diffusion", "stretch correction",
              "translucent shadow maps", "specular", "camera")


@dataclass(frozen=True)
class PassDecision:
    name: str
    on: bool
    why: str


@dataclass(frozen=True, eq=False)
class Plan:
    """The passes to run, their knobs and the reasons.

    Attributes
    ----------
    decisions : tuple of PassDecision, in pass order
    variances : ndarray (n,) [mm^2], the shared Gaussian variances
    profile_error : float, relative RMS error of that profile (worst channel)
    texture_size : int; taps : int; max_ratio : float (blur step growth)
    pixel_size : float [mm] footprint of a pixel at the object's nearest point
    """

    decisions: tuple
    variances: np.ndarray
    profile_error: float
    texture_size: int
    taps: int
    max_ratio: float
    pixel_size: float

    def on(self, name: str) -> bool:
        for d in self.decisions:
            if d.name == name:
                return d.on
        raise KeyError(f"no pass named {name!r}; passes: {', '.join(PASS_ORDER)}.")

    def replace(self, name: str, on: bool, why: str) -> "Plan":
        decisions = tuple(PassDecision(d.name, on, why) if d.name == name else d for d in self.decisions)
        return dataclasses.replace(self, decisions=decisions)

    def describe(self) -> str:
        width = max(len(d.name) for d in self.decisions)
        lines = [f"  {'on ' if d.on else 'off'}  {d.name:<{width}}  {d.why}" for d in self.decisions]
        knobs = (f"  knobs: {len(self.variances)} Gaussians (profile error {100 * self.profile_error:.2f} %), "
                 f"texture {self.texture_size}^2, {self.taps}-tap blur, steps grow variance <= {self.max_ratio:g}x")
        return "\n".join(["plan:"] + lines + [knobs])


def _pixel_footprint(scene: Scene) -> float:
    lo, hi = scene.mesh.bounds
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    nearest = max(np.linalg.norm(np.asarray(scene.camera.position) - center) - radius, 1e-3)
    return float(scene.camera.pixel_size(nearest))


def _uv_unit_length(scene: Scene) -> float:
    """Median world length [mm] of one unit of UV (area-weighted over faces and both axes)."""
    du, dv, _ = face_stretch(scene.mesh)
    lengths = np.concatenate([du, dv])
    return float(np.median(lengths[lengths > 0]))


def plan_scene(scene: Scene, *, accuracy: float | None = None) -> Plan:
    """The plan for ``scene`` (its own accuracy target unless ``accuracy`` is given)."""
    target = scene.accuracy if accuracy is None else accuracy
    material = scene.material
    decisions = {"texture geometry": (True, "positions, normals and stretch per texel (once per mesh)"),
                 "irradiance": (True, f"{len(scene.lights)} light(s) with Fresnel transmittance"),
                 "shadows": (True, "shadow map per light"),
                 "camera": (True, "rasterize, look up, tone map")}
    gs, error, reached = choose_variances(material, target / 2)
    variances, w = np.asarray(gs.variances), np.asarray(gs.weights)
    pixel = _pixel_footprint(scene)
    total = w.sum(0)
    rms = float(np.max(np.sqrt(np.maximum((2 * variances[:, None] * w).sum(0), 0) / np.maximum(total, 1e-300))))
    diffusion = rms >= pixel
    decisions["diffusion"] = (diffusion, (
        f"profile RMS radius {rms:.3g} mm {'>=' if diffusion else '<'} pixel footprint {pixel:.3g} mm"
        + ("" if diffusion else "; Lambert with the total albedo " + "/".join(f"{t:.3f}" for t in total))))
    if material.layers:
        decisions["layered profile"] = (True, f"{len(material.layers)} layers"
                                              + (" on a base" if material.base is not None else ""))
    else:
        decisions["layered profile"] = (False, f"material is {material.kind}, not layered")
    # Texture size: a texel no larger than the pixel footprint.
    unit = _uv_unit_length(scene)
    size = 64
    while size < scene.texture_size and unit / size > pixel:
        size *= 2
    size = min(size, scene.texture_size)
    variation = stretch_variation(scene.mesh)
    stretch = diffusion and variation >= STRETCH_THRESHOLD
    decisions["stretch correction"] = (stretch, f"UV stretch varies by {100 * variation:.0f} % "
                                                f"({'>=' if variation >= STRETCH_THRESHOLD else '<'} "
                                                f"{100 * STRETCH_THRESHOLD:.0f} %)"
                                       + ("" if diffusion else "; no diffusion to correct"))
    decisions["translucent shadow maps"] = _tsm_decision(scene, variances, w, target)
    spec = material.specular > 0
    decisions["specular"] = (spec, f"Beckmann m = {material.roughness:g}, weight {material.specular:g}"
                             if spec else "material specular = 0")
    if not reached:
        profile_pass = "layered profile" if material.layers else "diffusion"
        on, why = decisions[profile_pass]
        decisions[profile_pass] = (on, why + " (target not reachable with 12 Gaussians; best shown)")
    ordered = tuple(PassDecision(name, *decisions[name]) for name in PASS_ORDER)
    return Plan(ordered, variances, error, size, 7, 2.0 if target < 0.15 else 4.0, pixel)


def _tsm_decision(scene: Scene, variances, weights, target):
    """Thinnest part that light cuts through, from one face to an opposite one.

    Where light enters on a face turned the same way as the shadowed point (any shadowed
    point near the terminator of a convex body) the texture-space blur already carries
    that light around the surface; translucent shadow maps add light that crosses from a
    face to one turned away from it (normals more than 120 degrees apart): an ear, a fin,
    the far side of a ball.
    """
    texels = bake_texels(scene.mesh, 64)
    thinnest = np.inf
    for light in scene.lights:
        shadow = shadow_map(scene.mesh, light, size=128)
        g = light_geometry(texels.position, texels.normal, texels.mask, light, shadow)
        index = np.clip((g.front_uv * texels.size).astype(int), 0, texels.size - 1)
        front_normal = texels.normal[index[..., 1], index[..., 0]]
        through = (g.behind > 0) & ((front_normal * texels.normal).sum(-1) < -0.5)
        if through.any():
            thinnest = min(thinnest, float(np.percentile(g.thickness[through], 2)))
    if not np.isfinite(thinnest):
        return False, "no light crosses between opposite faces"
    w = np.abs(weights)
    share = float(np.max((w * np.exp(-thinnest**2 / (2 * variances))[:, None]).sum(0) / np.maximum(w.sum(0), 1e-300)))
    on = share >= 0.1 * target
    return on, (f"thinnest part light cuts through: {thinnest:.3g} mm, passing {share:.2e} of the profile's light "
                f"({'>=' if on else '<'} {0.1 * target:.2g})")
