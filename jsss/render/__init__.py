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

Every public name is imported on first use (PEP 562), so ``jsss.render.passes`` (the method
names a command line offers) and the other light modules load without JAX; ``from jsss.render
import render`` imports what it did before.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import types

# The module each public name comes from.
_SOURCES = {
    "image_space": ("SampledProfile", "camera_buffers", "image_space_exitance"),
    "linear_frame": ("LinearFrame", "linear_frame"),
    "mesh": ("Mesh", "box", "distance_to_rim", "fin", "load_obj", "plane", "uv_sphere"),
    "methods": ("ImageSpace", "Lambert", "NormalFiltering", "PixelPrepared", "RenderMethod", "TexturePrepared",
                "TextureSpace"),
    "passes": ("Method", "Pass"),
    "planner": ("PassDecision", "Plan", "deposit_change", "first_leg_change", "last_leg_change", "method_config",
                "plan_scene"),
    "prepared_renderer": ("PreparedRenderer", "prepare_renderer"),
    "profile_blend": ("ProfileBasis", "choose_basis"),
    "profile_choice": ("ProfileChoice", "choose_profile"),
    "reference": ("reference_radiance",),
    "renderer": ("FrameProgram", "RenderParams", "RenderResult", "frame_program", "prepare", "render", "render_image",
                 "render_params"),
    "scene": ("Material", "Scene", "SceneError", "load_scene", "parse_scene"),
    "surface_maps": ("MapParams", "SurfaceMaps"),
}
_MODULE_OF = {name: module for module, names in _SOURCES.items() for name in names}


def __getattr__(name: str):
    if name not in _MODULE_OF:
        if importlib.util.find_spec(f"{__name__}.{name}") is None:
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
        return importlib.import_module(f".{name}", __name__)  # a submodule, as the eager imports bound them
    value = getattr(importlib.import_module(f".{_MODULE_OF[name]}", __name__), name)
    globals()[name] = value  # once: the next look-up does not come here
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """``jsss.render.linear_frame`` is the function, as when this package imported it eagerly:
    the import system binds a submodule to its package's attribute of the same name when it
    first loads it, which would otherwise put the module ``linear_frame`` there."""

    def __setattr__(self, name, value):
        if name == "linear_frame" and isinstance(value, types.ModuleType):
            value = value.linear_frame
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package

__all__ = [
    "FrameProgram",
    "ImageSpace",
    "Lambert",
    "LinearFrame",
    "MapParams",
    "Material",
    "Mesh",
    "Method",
    "NormalFiltering",
    "Pass",
    "PassDecision",
    "PixelPrepared",
    "Plan",
    "PreparedRenderer",
    "ProfileBasis",
    "ProfileChoice",
    "RenderMethod",
    "RenderParams",
    "RenderResult",
    "SampledProfile",
    "Scene",
    "SceneError",
    "SurfaceMaps",
    "TexturePrepared",
    "TextureSpace",
    "box",
    "camera_buffers",
    "choose_basis",
    "choose_profile",
    "deposit_change",
    "distance_to_rim",
    "fin",
    "first_leg_change",
    "frame_program",
    "image_space_exitance",
    "last_leg_change",
    "linear_frame",
    "load_obj",
    "load_scene",
    "method_config",
    "parse_scene",
    "plan_scene",
    "plane",
    "prepare",
    "prepare_renderer",
    "reference_radiance",
    "render",
    "render_image",
    "render_params",
    "uv_sphere",
]
