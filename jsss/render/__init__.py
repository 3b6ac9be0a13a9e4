"""Subsurface rendering with a planner that picks the method a scene calls for.

Four methods: Lambert, normal filtering (Patro 2007), image-space integration with exact
dipole sampling (Mertens 2003) and texture-space diffusion (d'Eon 2007 sec. 5).
``load_scene`` reads a TOML scene, ``plan_scene`` chooses the method (from the measured
calibration table) and the passes and says why, ``render`` runs them. Frames are pure JAX
functions of the material and the lights, so they are differentiable in both;
``reference_radiance`` is the brute-force surface integral they are measured against.
Imports nothing from :mod:`fitting` or :mod:`measure`.
"""

from .image_space import SampledProfile, camera_buffers, image_space_exitance
from .mesh import Mesh, box, fin, load_obj, plane, uv_sphere
from .planner import Plan, PassDecision, plan_scene
from .renderer import Prepared, RenderParams, RenderResult, prepare, render, render_image, render_params
from .reference import reference_radiance
from .scene import Material, Scene, SceneError, load_scene, parse_scene

__all__ = [
    "Material", "Mesh", "PassDecision", "Plan", "Prepared", "RenderParams", "RenderResult", "SampledProfile",
    "Scene", "SceneError", "box", "camera_buffers", "fin", "image_space_exitance", "load_obj", "load_scene",
    "parse_scene", "plan_scene", "plane", "prepare", "reference_radiance", "render", "render_image",
    "render_params", "uv_sphere",
]
