"""Render one scene with every method and knob and measure each against the reference.

Used by ``benchmarks/methods.py`` (the accuracy-vs-time table and the planner's
calibration table) and by ``notebooks/methods.py``. The default reference is the transport
truth (``reference_radiance(profile_model="transport")``): the frames render with the
scene's own profile, and their error includes its distance from transport. Frames are
diffuse only (the specular lobe is the same in every method) and timed per frame after compilation (median
of ``repeats``); one-time geometry work (rasterizing, shadow maps, the Laplacian's
eigenvectors) is reported apart as ``prep_ms``; the part of it only that method does is the
calibration row's ``prep_ms``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from .calibration import CalibrationRow
from .mesh import is_closed
from .methods import TextureSpace
from .passes import Method, Pass
from .planner import SAMPLE_KNOBS, TEXTURE_KNOBS, plan_scene
from .reference import ReferenceFrame, reference_radiance
from .renderer import render
from .scene import Scene

__all__ = ["MethodFrame", "VARIANTS", "compare_methods", "relative_rms", "scene_at_distance"]

VARIANTS = ((Method.LAMBERT, {}),
            (Method.NORMAL_FILTERING, {"normal_filter": "naive"}),
            (Method.NORMAL_FILTERING, {"normal_filter": "spectral"}),
            *((Method.IMAGE_SPACE, {"samples": n}) for n in SAMPLE_KNOBS),
            *((Method.TEXTURE_SPACE, {"accuracy": a}) for a in TEXTURE_KNOBS))
_PREP = ("plan", "texture geometry", "shadows", "camera raster", "camera raster + shadows", "normal filter")
_OWN_PREP = ("texture geometry", "normal filter")  # one-time work only that method does


@dataclass(frozen=True, eq=False)
class MethodFrame:
    """One method's frame of a scene, its error against the reference and its cost."""

    row: CalibrationRow
    radiance: np.ndarray
    prep_ms: float
    gaussians: int  # texture space's number of Gaussians (0 for the other methods)


def relative_rms(image, reference, mask) -> float:
    """sqrt(mean |image - reference|^2) / sqrt(mean |reference|^2) over the object's pixels."""
    diff = (np.asarray(image) - reference)[mask]
    return float(np.sqrt(np.mean(diff**2) / np.mean(reference[mask] ** 2)))


def scene_at_distance(scene: Scene, factor: float, *, width: int, height: int, texture_size: int = 256) -> Scene:
    """``scene`` with its camera moved ``factor`` times as far from what it looks at, at a new resolution."""
    cam = scene.camera
    target = np.asarray(cam.look_at, float)
    position = target + factor * (np.asarray(cam.position, float) - target)
    camera = dataclasses.replace(cam, position=tuple(position), width=width, height=height)
    return dataclasses.replace(scene, camera=camera, texture_size=min(texture_size, scene.texture_size))


FIXED_RESOLUTION = (8, 6)  # pixels at which a pixel method's frame is its fixed part alone


def _fixed_ms(scene: Scene, plan, repeats: int) -> float:
    """Milliseconds of ``plan``'s frame of ``scene`` at :data:`FIXED_RESOLUTION`: the part of a
    pixel method's frame that does not grow with the pixels (the time model's fixed part)."""
    width, height = FIXED_RESOLUTION
    tiny = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, width=width, height=height))
    result = render(tiny, plan, dtype=jnp.float32, time_passes=True, repeats=repeats)
    return 1000 * sum(t for k, t in result.timings.items() if k not in _PREP)


def compare_methods(scene: Scene, name: str, *, reference: ReferenceFrame | None = None,
                    reference_samples: int = 400_000, variants=VARIANTS, repeats: int = 3, progress=None):
    """Frames of ``scene`` by every (method, knobs) in ``variants``, with their errors and times.

    Returns (reference, list of MethodFrame). ``progress`` (callable of a str) hears each frame.
    """
    if reference is None:
        reference = reference_radiance(scene, samples=reference_samples, profile_model="transport")
    frames = []
    for method, knobs in variants:
        plan = plan_scene(scene, method=method, **knobs)
        plan = plan.replace(Pass.SPECULAR, False, "diffuse only: the lobe is the same in every method")
        plan = plan.replace(Pass.SINGLE_SCATTERING, False, "diffusion only: the reference integrates the profile")
        # Its exit law is then that of every order, as the reference's, whose decision it follows.
        plan = plan.replace(Pass.EXIT_ANGLE, reference.exit_angle, "as the reference")
        if plan.method == Method.TEXTURE_SPACE:  # the one method that reads where the last leg began
            plan = plan.replace(Pass.LAST_LEG, reference.last_leg, "as the reference")
            plan = plan.replace(Pass.FIRST_LEG, reference.first_leg, "as the reference")
        result = render(scene, plan, dtype=jnp.float32, time_passes=True, repeats=repeats)
        frame_ms = 1000 * sum(t for k, t in result.timings.items() if k not in _PREP)
        fixed_ms = _fixed_ms(scene, plan, repeats) if method != Method.TEXTURE_SPACE else 0.0
        prep_ms = 1000 * sum(t for k, t in result.timings.items() if k in _PREP)
        own_ms = 1000 * sum(t for k, t in result.timings.items() if k in _OWN_PREP)
        work = plan.method_config.work(scene)
        knob = plan.knob
        features = plan.features
        row = CalibrationRow(name, round(plan.blur_pixels, 4), method, knob,
                             relative_rms(result.radiance, reference.radiance, reference.mask), round(frame_ms, 3),
                             int(work), round(own_ms, 3), is_closed(scene.mesh),
                             blur_frame=round(features.blur_frame, 6), backlit=round(features.backlit, 4),
                             curvature=round(features.curvature, 5), fixed_ms=round(min(fixed_ms, frame_ms), 3))
        gaussians = len(plan.variances) if isinstance(plan.method_config, TextureSpace) else 0
        frames.append(MethodFrame(row, result.radiance, prep_ms, gaussians))
        if progress is not None:
            progress(f"{name}: {method} {knob}: {100 * row.error:.2f} % in {frame_ms:.1f} ms")
    return reference, frames
