"""Texture-space subsurface rendering (d'Eon 2007 sec. 5) with a scene planner.

``load_scene`` reads a TOML scene, ``plan_scene`` decides which passes it needs and why,
``render`` runs them. The passes are pure JAX functions of the material's Gaussian
weights and the lights (:func:`render_image`), so frames are differentiable in both.
Imports nothing from :mod:`fitting` or :mod:`measure`.
"""

from .mesh import Mesh, box, fin, load_obj, plane, uv_sphere
from .planner import Plan, PassDecision, plan_scene
from .renderer import Prepared, RenderParams, RenderResult, prepare, render, render_image, render_params
from .scene import Material, Scene, SceneError, load_scene, parse_scene

__all__ = [
    "Material", "Mesh", "PassDecision", "Plan", "Prepared", "RenderParams", "RenderResult", "Scene",
    "SceneError", "box", "fin", "load_obj", "load_scene", "parse_scene", "plan_scene", "plane", "prepare",
    "render", "render_image", "render_params", "uv_sphere",
]
