"""Scene files the commands write (tomlkit): a new scene around a fitted medium
(``fit-params --scene``), and a user's scene with its ``[material]`` replaced by a fit
(``jsss-render fit``), keeping the rest of the file, comments included; and a fitted material
for other renderers (``--export``, both commands), with a fitted colour map as their textures.

The scene format, and its checks with their did-you-mean messages, are
:mod:`jsss.render.scene`'s; this module only writes what that reads.
"""

from __future__ import annotations

import numpy as np
import tomlkit

__all__ = ["EXPORTS", "MAP_EXPORTS", "export_material", "fitted_material", "scene_with_material", "sphere_scene"]

EXPORTS = {"mitsuba": "_mitsuba.xml", "pbrt": ".pbrt", "blender": "_blender.py"}  # the file each writes, after a prefix
MAP_EXPORTS = {"mitsuba": "_mitsuba_transmittance.exr", "blender": "_blender_colour.exr"}  # and its texture


def _rgb(values) -> list[float]:
    return [float(v) for v in np.broadcast_to(np.asarray(values, float), (3,))]


def fitted_material(medium, *, profile: str, g: float, roughness: float = 0.35, specular: float | None = None,
                    comment: str | None = None):
    """A ``[material]`` table of a homogeneous medium (coefficients in 1/mm) and the profile
    model it was fitted with (``"dipole"`` or ``"transport"`` with ``g``)."""
    if profile not in ("dipole", "transport"):
        raise ValueError(f"profile must be 'dipole' or 'transport'; got {profile!r}.")
    table = tomlkit.table()
    if comment:
        table.add(tomlkit.comment(comment))
    table.add("sigma_a", _rgb(medium.sigma_a))
    table.add("sigma_s_prime", _rgb(medium.sigma_s_prime))
    table.add("eta", _rgb(medium.eta))
    table.add("roughness", float(roughness))
    if specular is not None:
        table.add("specular", float(specular))
    table.add("profile", profile)
    table.add("g", float(g))
    return table


def sphere_scene(material, *, label: str) -> str:
    """A scene (TOML text) that shows ``material`` on a 20 mm sphere under a key light;
    ``jsss-render`` renders it as it is. Edit geometry, lights and camera to taste."""
    doc = tomlkit.document()
    doc.add(tomlkit.comment(f"{label}: written by jsss; lengths in mm, coefficients in 1/mm"))
    doc.add("geometry", tomlkit.table().add("shape", "sphere").add("radius", 20.0))
    doc.add("material", material)
    lights = tomlkit.aot()
    lights.append(tomlkit.table().add("type", "directional").add("direction", [0.6, 0.8, -0.5])
                  .add("color", [1.0, 1.0, 1.0]).add("intensity", 1.0))
    doc.add("lights", lights)
    doc.add("camera", tomlkit.table().add("position", [0.0, -110.0, 30.0]).add("look_at", [0.0, 0.0, 0.0])
            .add("fov", 28).add("resolution", [320, 240]))
    doc.add("render", tomlkit.table().add("accuracy", 0.05).add("texture_size", 512))
    return tomlkit.dumps(doc)


def scene_with_material(scene_text: str, material) -> str:
    """``scene_text`` with its ``[material]`` table and sub-tables (``[material.gaussians]``,
    ``[[material.layers]]``, wherever they stand) replaced by ``material``, in place; every other
    table, key and comment is kept as written."""
    doc = tomlkit.parse(scene_text)
    doc["material"] = material
    return tomlkit.dumps(doc)


def export_material(kinds, prefix, medium, *, g: float, unit_mm: float, albedo_map=None) -> list:
    """Write ``medium`` for each renderer in ``kinds`` (:data:`EXPORTS`' keys) to ``PREFIX`` plus
    the format's suffix, atomically; with ``albedo_map`` (a pre-post colour map, rows with v
    increasing) also each format's texture beside it, in the map files' layout (bottom row
    v = 0): Mitsuba's sqrt(c) transmittance and Cycles' Base Color (:mod:`measure.export`'s
    "Colour maps"). pbrt takes no map (ValueError: the command checks it first). Returns
    ``(kind, path)`` of each file written."""
    from pathlib import Path

    from measure import export
    from measure.exr import write_exr

    from ._console import write_text

    prefix, written = Path(prefix), []
    for kind in dict.fromkeys(kinds):
        path = prefix.with_name(prefix.name + EXPORTS[kind])
        options = {"g": g, "unit_mm": unit_mm, "name": prefix.name}
        if albedo_map is not None:
            if kind not in MAP_EXPORTS:
                raise ValueError(f"the {kind} export takes no colour map (maps go to {', '.join(MAP_EXPORTS)})")
            texture = prefix.with_name(prefix.name + MAP_EXPORTS[kind])
            image = (export.prepost_transmittance(albedo_map) if kind == "mitsuba"
                     else export.blender_colour_map(medium, albedo_map, g=g))
            write_exr(texture, image[::-1].astype(np.float32))
            if kind == "mitsuba":  # Mitsuba resolves the name beside the XML
                options["transmittance"] = texture.name
            else:  # the script looks in the folder written to first, then beside itself
                options["colour_map"] = str(texture)
            written.append((f"{kind} texture", texture))
        writer = {"mitsuba": export.mitsuba_xml, "pbrt": export.pbrt_material, "blender": export.blender_python}[kind]
        write_text(path, writer(medium, **options))
        written.append((f"{kind} material", path))
    return written
