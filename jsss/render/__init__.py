"""Subsurface rendering with a planner that picks the method a scene calls for.

Four methods, each an immutable configuration (:mod:`jsss.render.methods`): ``Lambert``,
``NormalFiltering`` (Patro 2007), ``ImageSpace`` integration with exact dipole sampling
(Mertens 2003) and ``TextureSpace`` diffusion (d'Eon 2007 sec. 5). ``load_scene`` reads a
TOML scene, ``plan_scene`` chooses the method (from the measured calibration table) and the
passes and says why, ``render`` runs them. A material may vary over the surface
(``[material.maps]``: a colour map by d'Eon's texturing rules, parameter maps blended from a
few basis profiles; :mod:`jsss.render.surface_maps`, :mod:`jsss.render.profile_blend`).
Frames are pure JAX functions of the material and
the lights, so they are differentiable in both; ``linear_frame`` keeps a texture-space frame
as the weighted sum of fixed blurs that a fit solves with; ``reference_radiance`` is the
brute-force surface integral they are measured against. Warm frames neither rasterize nor
compile again: the geometry is kept while the mesh, camera and lights' positions stay
(:mod:`jsss.render.memory`), compiled frames per layout of the geometry
(:mod:`jsss.render.programs`), and ``prepare_renderer`` readies a scene for a loop over
materials or light intensities. Imports nothing from :mod:`fitting` or :mod:`measure`.
"""

from .image_space import SampledProfile, camera_buffers, image_space_exitance
from .linear_frame import LinearFrame, linear_frame
from .mesh import Mesh, box, distance_to_rim, fin, load_obj, plane, uv_sphere
from .methods import (ImageSpace, Lambert, NormalFiltering, PixelPrepared, RenderMethod, TexturePrepared,
                      TextureSpace)
from .passes import Method, Pass
from .planner import PassDecision, Plan, deposit_change, method_config, plan_scene
from .prepared_renderer import PreparedRenderer, prepare_renderer
from .profile_blend import ProfileBasis, choose_basis
from .reference import reference_radiance
from .renderer import (FrameProgram, RenderParams, RenderResult, frame_program, prepare, render, render_image,
                       render_params)
from .scene import Material, Scene, SceneError, load_scene, parse_scene
from .surface_maps import MapParams, SurfaceMaps

__all__ = [
    "FrameProgram", "ImageSpace", "Lambert", "LinearFrame", "MapParams", "Material", "Mesh", "Method",
    "NormalFiltering", "Pass", "PassDecision", "PixelPrepared", "Plan", "PreparedRenderer", "ProfileBasis",
    "RenderMethod", "RenderParams", "RenderResult", "SampledProfile", "Scene", "SceneError", "SurfaceMaps",
    "TexturePrepared", "TextureSpace", "box", "camera_buffers", "choose_basis", "deposit_change", "distance_to_rim",
    "fin", "frame_program", "image_space_exitance", "linear_frame", "load_obj", "load_scene", "method_config",
    "parse_scene", "plan_scene", "plane", "prepare", "prepare_renderer", "reference_radiance", "render",
    "render_image", "render_params", "uv_sphere",
]
