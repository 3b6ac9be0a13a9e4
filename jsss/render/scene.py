"""Scenes: one object, its material, lights, a camera and an accuracy target, from TOML.

A scene file (lengths in mm, coefficients in 1/mm)::

    [geometry]
    shape = "sphere"          # sphere | plane | box | fin | mesh (obj: the same)
    radius = 20.0             # shape parameters (see jsss.render.mesh); mesh: path = "head.glb" (OBJ or
                              # glTF; units = "mm" | "cm" | "m" | "in", default mm for OBJ and m for glTF;
                              # textures = true: its base-colour texture is the colour map)

    [material]
    name = "marble"           # a measured material (`jsss materials`), or sigma_a/sigma_s_prime/eta,
                              # or preset = "skin", or [[material.layers]] (+ [material.base]),
                              # or [material.gaussians] variances/weights/eta
    roughness = 0.35          # specular lobe (Beckmann m); specular = 0 turns it off
    texturing = "pre-post"    # d'Eon's rule for a colour map: pre-post | pre | post
    profile = "auto"          # a homogeneous medium's profile: auto (the default: the dipole where
                              # its R_d is within a quarter of the accuracy of the transport tables',
                              # else the tables; jsss.render.profile_choice) | dipole | transport;
                              # g = 0 is its Henyey-Greenstein g

    [material.maps]           # optional, image files next to the scene (jsss.render.surface_maps)
    albedo = "veins.png"      # colour map: 8/16-bit sRGB or linear EXR, in [0, 1]
    sigma_a = "sa.exr"        # parameter maps, linear EXR [1/mm] (either, or both), or
                              # diffuse_reflectance (colour) and mean_free_path (EXR, mm)

    [[lights]]
    type = "directional"      # or "point" with position = [x, y, z], or "environment" with
                              # map = "sky.exr" (linear lat-long, +z up; none: a constant color)
                              # and rotation (degrees about +z): jsss.render.environment
    direction = [-1, 0.3, -1] # the direction light travels
    color = [1, 1, 1]
    intensity = 1.0

    [camera]
    position = [0, -120, 40]
    look_at = [0, 0, 0]
    fov = 30                  # vertical, degrees
    resolution = [320, 240]

    [render]
    accuracy = 0.05           # target relative error of the subsurface light
    texture_size = 512        # the largest texture the planner may choose
    method = "auto"           # or lambert | normal filtering | image-space | texture-space: fixes it

Every problem is reported as ``file: [table] key: what is wrong`` (:class:`SceneError`).
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import jax
import numpy as np

from .. import layers as _layers
from .. import transport as _transport
from ..gaussians.gaussian_sum import GaussianSum
from ..materials import material as _library_material
from ..medium import Medium
from ..numerics import is_concrete
from . import budget
from . import mesh as _mesh
from .artist_maps import coefficients_from_artist_maps
from .environment import Environment
from .lighting import Light
from .passes import Method
from .profile_choice import MODELS as PROFILE_MODELS
from .profile_choice import ProfileChoice, choose_profile, map_media
from .raster import PerspectiveView
from .surface_maps import (
    ARTIST_KEYS,
    COEFFICIENT_KEYS,
    MAP_KEYS,
    TEXTURING,
    MapError,
    SurfaceMaps,
    read_map,
)

__all__ = ["Material", "Scene", "SceneError", "load_scene", "parse_scene"]


class SceneError(ValueError):
    """A scene file or table is invalid; the message names the file, the key and the problem."""


@dataclass(frozen=True, eq=False)
class Material:
    """What the renderer needs of a material: its profile's source and its surface.

    Exactly one of ``medium`` (homogeneous, semi-infinite), ``layers`` (+ optional ``base``)
    or ``gaussians`` (a given profile) is set. ``eta`` (3,) is the index the surface's
    Fresnel terms use (the top layer's for a stack). A homogeneous medium's profile is the
    dipole or :mod:`jsss.transport` (exact to radiative transfer) with Henyey-Greenstein
    ``g``: ``profile_model = "auto"`` (the default) keeps the dipole where its predicted error
    against the transport truth is within a quarter of the accuracy target (a scene's, else
    5 %) and takes the transport tables otherwise; ``"dipole"`` or ``"transport"`` is obeyed.
    Building the material resolves it (:mod:`jsss.render.profile_choice`), so
    ``profile_model`` then names the model used and ``profile`` holds the choice, its reasons
    and both models' predicted errors (None for a stack, a given profile, or a traced medium).
    ``dataclasses.replace`` keeps the request: a new medium under ``auto`` is chosen for again;
    to pin a model, pass ``profile_model=...`` with ``profile=None``. ``maps`` (:class:`SurfaceMaps`) vary
    the material over the surface; ``normalize_profile`` scales the profile's total to 1 per
    channel, so that a colour map alone sets the colour (d'Eon 2007 sec. 5.3).
    """

    label: str
    eta: np.ndarray
    medium: Medium | None = None
    layers: tuple = ()
    base: Medium | None = None
    gaussians: GaussianSum | None = None
    specular: float = 1.0
    roughness: float = 0.35
    profile_model: str = "auto"
    g: float = 0.0
    maps: SurfaceMaps | None = None
    normalize_profile: bool = False
    profile: ProfileChoice | None = None

    def __post_init__(self):
        if self.profile_model not in PROFILE_MODELS:
            raise ValueError(f"profile_model must be one of {', '.join(PROFILE_MODELS)}; got {self.profile_model!r}.")
        if self.medium is None or self.layers or self.gaussians is not None:
            object.__setattr__(self, "profile", None)
            return
        if not is_concrete(self.medium):  # under jit or grad: the caller fixed the model
            if self.profile_model == "auto":
                raise ValueError("profile_model 'auto' is chosen from the medium's numbers, and this medium is "
                                 "traced (jit or grad); give 'dipole' or 'transport'.")
            object.__setattr__(self, "profile", None)
            return
        # dataclasses.replace keeps the old choice: an unchanged model keeps its request and
        # target ("auto" stays auto for a new medium); a changed model is a new request.
        kept = self.profile is not None and self.profile_model in (self.profile.model, self.profile.requested)
        requested = self.profile.requested if kept else self.profile_model
        target = self.profile.target if kept else 0.05
        with jax.ensure_compile_time_eval():  # a concrete medium built inside someone's jit
            choice = choose_profile(self.medium, g=self.g, requested=requested, target=target,
                                    texels=map_media(self.maps, self.eta))
        object.__setattr__(self, "profile_model", choice.model)
        object.__setattr__(self, "profile", choice)

    @property
    def kind(self) -> str:
        if self.gaussians is not None:
            return "gaussians"
        return "layers" if self.layers else "medium"


@dataclass(frozen=True, eq=False)
class Scene:
    mesh: _mesh.Mesh
    material: Material
    lights: tuple
    camera: PerspectiveView
    accuracy: float = 0.05
    texture_size: int = 512
    shadow_map_size: int = 512
    exposure: float | None = None
    source: str = "<scene>"
    method: str | None = None  # [render] method: the scene fixes it; None lets the planner choose
    extras: dict = field(default_factory=dict)

    def with_accuracy(self, accuracy: float) -> Scene:
        """This scene at another accuracy target, with a ``profile = "auto"`` material chosen
        again for it (:mod:`jsss.render.profile_choice`; the artist's maps keep the model their
        coefficients were converted with)."""
        material, choice = self.material, self.material.profile
        artist = material.maps is not None and any(key in ARTIST_KEYS for key, _ in material.maps.files)
        if choice is not None and choice.requested == "auto" and choice.target != accuracy and not artist:
            material = dataclasses.replace(material, profile_model="auto", profile=ProfileChoice(
                choice.model, "auto", choice.why, accuracy))
        return dataclasses.replace(self, accuracy=accuracy, material=material)


class _Table:
    """Typed reads from one TOML table with errors that name the file, table and key."""

    def __init__(self, data, name: str, source: str):
        if not isinstance(data, dict):
            raise SceneError(f"{source}: [{name}] must be a table; got {type(data).__name__}.")
        self.data, self.name, self.source = data, name, source
        self.used = set()

    def fail(self, key: str, problem: str):
        raise SceneError(f"{self.source}: [{self.name}] {key}: {problem}")

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=...):
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                self.fail(key, "missing (required).")
            return default
        return self.data[key]

    def number(self, key: str, default=..., *, positive=False, nonnegative=False, integer=False):
        value = self.raw(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f"must be a number; got {value!r}.")
        if integer and int(value) != value:
            self.fail(key, f"must be an integer; got {value!r}.")
        if not np.isfinite(value):
            self.fail(key, f"must be finite; got {value!r}.")
        if positive and value <= 0:
            self.fail(key, f"must be > 0; got {value!r}.")
        if nonnegative and value < 0:
            self.fail(key, f"must be >= 0; got {value!r}.")
        return int(value) if integer else float(value)

    def vector(self, key: str, n: int, default=..., *, nonnegative=False, positive=False, scalar_ok=False):
        value = self.raw(key, default)
        if scalar_ok and isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value] * n
        if not isinstance(value, (list, tuple)) or len(value) != n or \
                not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
            self.fail(key, f"must be a list of {n} numbers; got {value!r}.")
        arr = np.asarray(value, float)
        if not np.all(np.isfinite(arr)):
            self.fail(key, f"must be finite; got {value!r}.")
        if nonnegative and np.any(arr < 0):
            self.fail(key, f"must be >= 0 (a negative coefficient is unphysical); got {value!r}.")
        if positive and np.any(arr <= 0):
            self.fail(key, f"must be > 0; got {value!r}.")
        return arr

    def string(self, key: str, choices=None, default=...):
        value = self.raw(key, default)
        if not isinstance(value, str):
            self.fail(key, f"must be a string; got {value!r}.")
        if choices is not None and value not in choices:
            self.fail(key, f"must be one of {', '.join(choices)}; got {value!r}.")
        return value

    def check_unknown(self, known=None):
        """Refuse keys not read (or not in ``known``), suggesting the nearest valid name."""
        valid = self.used if known is None else set(known)
        unknown = sorted(set(self.data) - valid)
        if unknown:
            close = difflib.get_close_matches(unknown[0], sorted(valid), n=1)
            hint = f" did you mean {close[0]!r}?" if close else f" valid: {', '.join(sorted(valid))}."
            value = self.data[unknown[0]]
            tables = isinstance(value, dict) or (isinstance(value, list) and value and all(isinstance(v, dict) for v in value))
            kind = "section" if tables else "key"
            self.fail(unknown[0], f"unknown {kind} (misspelt?);{hint}")


_SECTIONS = ("geometry", "material", "lights", "camera", "render")
_SHAPES = ("sphere", "plane", "box", "fin", "mesh", "obj")  # obj: the older name of mesh


def _segments(t: _Table, key: str, default: int, triangles) -> int:
    """An integer tessellation count, refused before the mesh is built when its ``triangles(n)``
    would not fit in memory (:mod:`jsss.render.budget`)."""
    n = t.number(key, default, integer=True, positive=True)
    problem = budget.check_size(triangles(n), budget.BYTES_PER_TRIANGLE, f"{n:,} {key} ({triangles(n):,.0f} triangles)")
    if problem:
        t.fail(key, problem)
    return n


def _inside(t: _Table, key: str, path: Path, base_dir: Path, allow_outside: bool) -> Path:
    """``path`` as the scene names it, resolved against the scene's folder; one that leaves the
    folder (an absolute path, ``..``) only where the user allows it: a scene from elsewhere must
    not make jsss read any file it names."""
    full = path if path.is_absolute() else base_dir / path
    if not allow_outside:
        try:
            full.resolve().relative_to(base_dir.resolve())
        except ValueError:
            t.fail(key, f"{path} is outside the scene's folder {base_dir}; move it beside the scene, or allow "
                        "paths outside (jsss-render --allow-outside-paths, parse_scene(allow_outside=True)).")
    return full


def _geometry(t: _Table, base_dir: Path, allow_outside: bool = False) -> tuple[_mesh.Mesh, np.ndarray | None, str]:
    """The mesh in mm, and a mesh file's base-colour texture (linear, texel order; None without
    one, or with ``textures = false``) and where it came from."""
    shape = t.string("shape", _SHAPES)
    base_colour, unit = None, 1.0
    try:
        if shape == "sphere":
            radius = t.number("radius", 10.0, positive=True)
            rings = _segments(t, "rings", 48, lambda n: 2 * 3 * n)  # at least 3 segments a ring
            segments = _segments(t, "segments", 96, lambda n: 2 * n * rings)
            m = _mesh.uv_sphere(radius, segments=segments, rings=rings)
        elif shape == "plane":
            width = t.number("width", 40.0, positive=True)
            m = _mesh.plane(width, t.number("depth", width, positive=True),
                            segments=_segments(t, "segments", 1, lambda n: 2 * n * n))
        elif shape == "box":
            m = _mesh.box(t.vector("size", 3, (20.0, 20.0, 20.0), positive=True, scalar_ok=True),
                          segments=_segments(t, "segments", 8, lambda n: 12 * n * n))
        elif shape == "fin":
            m = _mesh.fin(t.number("height", 30.0, positive=True), t.number("radius", 40.0, positive=True),
                          t.number("thickness", 2.0, positive=True),
                          arc_degrees=t.number("arc_degrees", 60.0, positive=True),
                          segments=_segments(t, "segments", 32, lambda n: 8 * n * n))
        else:
            obj = _inside(t, "path", Path(t.string("path")), base_dir, allow_outside)
            units = t.string("units", tuple(_mesh.MM_PER_UNIT), _mesh.MESH_FILES.get(obj.suffix.lower(), "mm"))
            unit = _mesh.MM_PER_UNIT[units]
            m, base_colour = _mesh.load_mesh(obj)
            textures = t.raw("textures", True)
            if not isinstance(textures, bool):
                t.fail("textures", f"must be true or false; got {textures!r}.")
            if not textures:
                base_colour = None
    except ValueError as error:
        if isinstance(error, SceneError):
            raise
        if shape in ("mesh", "obj"):  # the file is at fault, not the key
            t.fail("path", f"{obj}: {error}" if str(obj) not in str(error) else str(error))
        t.fail("shape", str(error))
    scale = t.number("scale", 1.0, positive=True) * unit
    translate = t.vector("translate", 3, (0.0, 0.0, 0.0))
    t.check_unknown()
    size = float(np.ptp(np.asarray(m.vertices, float), axis=0).max())
    where = ("path", f"{obj}: ") if shape in ("mesh", "obj") else ("shape", "")
    if not size > 0:
        t.fail(where[0], f"{where[1]}the mesh has no extent: every vertex is at one point.")
    extent = size * scale
    if shape in ("mesh", "obj") and scale == unit and not MIN_EXTENT <= size * unit <= MAX_EXTENT:  # the file's units
        t.fail("path", f"{obj}: its vertices span {size:.3g} units; jsss works in millimetres, from {MIN_EXTENT:g} "
                       f"to {MAX_EXTENT:g} mm across (give [geometry] units = \"mm\", \"cm\", \"m\" or \"in\", or a scale)")
    if not MIN_EXTENT <= extent <= MAX_EXTENT:
        t.fail("scale", f"{scale:g} makes the object {extent:.3g} mm across; jsss works in millimetres, from "
                        f"{MIN_EXTENT:g} mm to {MAX_EXTENT:g} mm (a scale of {MAX_EXTENT / size:.3g} at most "
                        f"and {MIN_EXTENT / size:.3g} at least).")
    if np.any(np.abs(translate) > MAX_EXTENT):
        t.fail("translate", f"must lie within {MAX_EXTENT:g} mm of the origin; got {translate.tolist()}.")
    if scale != 1.0 or np.any(translate != 0):
        m = m.transformed(scale=scale, translate=translate)
    return m, base_colour, (f"{obj} (its base-colour texture)" if base_colour is not None else "")


MIN_EXTENT, MAX_EXTENT = 1e-3, 1e7  # mm: a micron to ten kilometres, where float32 still resolves a profile
ETA_RANGE = (0.5, 4.0)  # relative indices of refraction a material may have (water 1.33, diamond 2.42)
MAX_ROUGHNESS = 1.0  # Beckmann slope RMS m: 1 is already a matte, 45-degree facet spread
MAX_RADIANT = 1e15  # colour x intensity: the frame multiplies it by factors up to ~1e20 and float32 ends at 3e38
MAX_COEFFICIENT = 1e6  # 1/mm: a mean free path of 1 nm; beyond it no profile is resolved by any mesh or texture


def _medium(t: _Table, prefix: str = "") -> Medium:
    sigma_a = t.vector("sigma_a", 3, nonnegative=True, scalar_ok=True)
    sigma_s = t.vector("sigma_s_prime", 3, nonnegative=True, scalar_ok=True)
    eta = _eta(t, "eta")
    if np.any(sigma_a + sigma_s <= 0):
        t.fail("sigma_s_prime", "sigma_a + sigma_s_prime must be > 0 in every channel (no medium otherwise).")
    for key, value in (("sigma_a", sigma_a), ("sigma_s_prime", sigma_s)):
        if np.any(np.asarray(value) > MAX_COEFFICIENT):
            t.fail(key, f"{np.asarray(value).tolist()} 1/mm: above {MAX_COEFFICIENT:g} (a mean free path under 1 nm) "
                        "no profile is resolved; coefficients are in 1/mm (1 per cm is 0.1).")
    return Medium(sigma_a, sigma_s, eta)


def _eta(t: _Table, key: str):
    eta = t.vector(key, 3, (1.3, 1.3, 1.3), positive=True, scalar_ok=True)
    if np.any(eta <= ETA_RANGE[0]) or np.any(eta >= ETA_RANGE[1]):
        t.fail(key, f"a relative index of refraction must lie in ({ETA_RANGE[0]:g}, {ETA_RANGE[1]:g}) "
                    f"(water 1.33, skin 1.4, marble 1.5); got {eta.tolist()}.")
    return eta


def _maps(t: _Table, material: Material, texturing: str, base_dir: Path, allow_outside: bool = False) -> SurfaceMaps:
    """Read ``[material.maps]``: the colour map and the parameter maps, checked against the material."""
    files = {}
    for key in MAP_KEYS:
        if t.has(key):
            path = Path(t.string(key))
            files[key] = _inside(t, key, path, base_dir, allow_outside)
    t.check_unknown(MAP_KEYS)
    if not files:
        t.fail("albedo", f"give at least one map: {', '.join(MAP_KEYS)}.")
    given = lambda keys: [k for k in keys if k in files]  # noqa: E731
    coefficients, artist = given(COEFFICIENT_KEYS), given(ARTIST_KEYS)
    if coefficients and artist:
        t.fail(artist[0], f"give sigma maps ({', '.join(coefficients)}) or the artist's maps "
                          f"({', '.join(artist)}), not both.")
    if (coefficients or artist) and material.kind != "medium":
        t.fail((coefficients or artist)[0], f"parameter maps vary a homogeneous medium; this material is "
                                            f"{material.kind} (a colour map, albedo, works with any material).")
    if (coefficients or artist) and material.normalize_profile:
        t.fail((coefficients or artist)[0], "normalize_profile and parameter maps contradict each other: "
                                            "the maps set the profile's total.")
    try:
        read = {k: read_map(p, k, encoded_ok=k in ("albedo", "diffuse_reflectance")) for k, p in files.items()}
    except MapError as error:
        raise SceneError(str(error)) from None
    for key, values in read.items():
        if key in ("albedo", "diffuse_reflectance") and np.any(values > 1):
            t.fail(key, f"{files[key]}: a reflectance must lie in [0, 1]; its largest value is {values.max():.4g} "
                        "(an EXR colour map must be linear reflectance, not radiance).")
        if np.any(values < 0):
            t.fail(key, f"{files[key]}: must be >= 0; its smallest value is {values.min():.4g}.")
        if key == "mean_free_path" and np.any(values <= 0):
            t.fail(key, f"{files[key]}: a mean free path must be > 0 [mm]; its smallest value is {values.min():.4g}.")
    pair = coefficients or artist
    if len(pair) == 2 and read[pair[0]].shape != read[pair[1]].shape:
        t.fail(pair[1], f"{files[pair[1]]} is {read[pair[1]].shape[1]} x {read[pair[1]].shape[0]} pixels but "
                        f"{pair[0]} ({files[pair[0]]}) is {read[pair[0]].shape[1]} x {read[pair[0]].shape[0]}; "
                        "parameter maps must have one size.")
    sigma_a = sigma_s = None
    if pair:
        shape = read[pair[0]].shape
        medium = material.medium
        if coefficients:
            sigma_a = read.get("sigma_a", np.broadcast_to(np.asarray(medium.sigma_a, float), shape))
            sigma_s = read.get("sigma_s_prime", np.broadcast_to(np.asarray(medium.sigma_s_prime, float), shape))
            if np.any(sigma_a + sigma_s <= 0):
                t.fail(pair[0], "sigma_a + sigma_s_prime must be > 0 at every texel (no medium otherwise).")
        else:
            try:
                sigma_a, sigma_s = coefficients_from_artist_maps(
                    medium, read.get("diffuse_reflectance"), read.get("mean_free_path"), shape,
                    profile_model=material.profile_model, g=material.g)
            except ValueError as error:
                t.fail(artist[0], f"{files[artist[0]]}: {error}")
    return SurfaceMaps(read.get("albedo"), sigma_a, sigma_s, texturing, tuple((k, str(p)) for k, p in files.items()))


def _material(t: _Table, source: str, base_dir: Path = Path("."), allow_outside: bool = False,
              mesh_colour=(None, "")) -> Material:
    surface = dict(specular=t.number("specular", 1.0, nonnegative=True),
                   roughness=t.number("roughness", 0.35, positive=True))
    if surface["roughness"] > MAX_ROUGHNESS:
        t.fail("roughness", f"is Beckmann's slope RMS m and must lie in (0, {MAX_ROUGHNESS:g}] (0.25-0.35 for "
                            f"polished stone and skin); got {surface['roughness']:g}.")
    forms = [k for k in ("name", "sigma_a", "preset", "layers", "gaussians") if t.has(k)]
    if len(forms) != 1:
        t.fail("name", "give exactly one of name, sigma_a/sigma_s_prime/eta, preset, layers or gaussians; "
                       f"got {forms or 'none'}.")
    form = forms[0]
    if form == "name":
        name = t.string("name")
        try:  # a measured material of jsss.materials: Jensen 2001 or Narasimhan 2006
            medium = _library_material(name)
        except ValueError as error:
            t.fail("name", str(error))
        material = Material(name, np.asarray(medium.eta), medium=medium, **surface)
    elif form == "sigma_a":
        medium = _medium(t)
        if np.any(np.asarray(medium.sigma_s_prime) <= 0):
            t.fail("sigma_s_prime", "must be > 0 in every channel: a medium that scatters nothing returns no "
                                    f"light from below its surface; got {np.asarray(medium.sigma_s_prime).tolist()}.")
        material = Material("custom", np.asarray(medium.eta), medium=medium, **surface)
    elif form == "preset":
        t.string("preset", ("skin",))
        layers, base = _layers.skin_three_layer()
        material = Material("skin (3 layers)", np.asarray(layers[0].medium.eta), layers=tuple(layers), base=base,
                            **surface)
    elif form == "layers":
        entries = t.raw("layers")
        if not isinstance(entries, list) or not entries:
            t.fail("layers", "must be a non-empty array of tables ([[material.layers]]).")
        layers = []
        for i, entry in enumerate(entries):
            lt = _Table(entry, f"material.layers[{i}]", source)
            layers.append(_layers.Layer(_medium(lt), lt.number("thickness", positive=True)))
            lt.check_unknown()
        base = None
        if t.has("base"):
            bt = _Table(t.raw("base"), "material.base", source)
            base = _medium(bt)
            bt.check_unknown()
        material = Material(f"{len(layers)} layers" + (" on a base" if base is not None else ""),
                            np.asarray(layers[0].medium.eta), layers=tuple(layers), base=base, **surface)
    else:
        gt = _Table(t.raw("gaussians"), "material.gaussians", source)
        variances = np.asarray(gt.raw("variances"), float)
        weights = np.asarray(gt.raw("weights"), float)
        if variances.ndim != 1 or np.any(variances <= 0) or np.any(np.diff(variances) <= 0):
            gt.fail("variances", f"must be positive and increasing [mm^2]; got {variances.tolist()}.")
        if weights.shape != (len(variances), 3) or np.any(weights < 0):
            gt.fail("weights", f"must be {len(variances)} non-negative [r, g, b] rows; got shape {weights.shape}.")
        eta = _eta(gt, "eta")
        gt.check_unknown()
        material = Material("given Gaussians", eta, gaussians=GaussianSum(weights, variances), **surface)
    if t.has("profile") or t.has("g"):
        model = t.string("profile", PROFILE_MODELS, "auto")
        g = t.number("g", 0.0)
        if model == "transport":
            if material.medium is None:
                t.fail("profile", f"'transport' needs a homogeneous medium; this material is {material.kind}.")
            try:
                _transport.check_supported(material.medium.eta, g)
                _transport.check_medium(material.medium, g=g)
            except ValueError as error:
                t.fail("profile", str(error))
        material = dataclasses.replace(material, profile_model=model, g=float(g), profile=None)
    texturing = t.string("texturing", TEXTURING, "pre-post")
    normalize = t.raw("normalize_profile", False)
    if not isinstance(normalize, bool):
        t.fail("normalize_profile", f"must be true or false; got {normalize!r}.")
    material = dataclasses.replace(material, normalize_profile=normalize)
    if t.has("maps"):
        maps = _maps(_Table(t.raw("maps"), "material.maps", source), material, texturing, base_dir, allow_outside)
        material = dataclasses.replace(material, maps=maps)
    colour, colour_source = mesh_colour
    if colour is not None and (material.maps is None or material.maps.albedo is None):
        # the mesh file's base-colour texture is the colour map, unless [material.maps] gives one
        old = material.maps
        maps = SurfaceMaps(colour, None if old is None else old.sigma_a, None if old is None else old.sigma_s_prime,
                           texturing, (("albedo", colour_source),) + (() if old is None else old.files))
        material = dataclasses.replace(material, maps=maps)
    t.check_unknown()
    return material


def _light(t: _Table, base_dir: Path = Path("."), allow_outside: bool = False) -> Light | Environment:
    kind = t.string("type", ("point", "directional", "environment"))
    color = tuple(t.vector("color", 3, (1.0, 1.0, 1.0), nonnegative=True))
    intensity = t.number("intensity", 1.0, nonnegative=True)
    if intensity * max(color) > MAX_RADIANT:
        t.fail("intensity", f"{intensity:g} times the colour's {max(color):g} exceeds {MAX_RADIANT:g}: the frame "
                            "would overflow float32 once multiplied by the shading; scale the light and the "
                            "exposure down together.")
    if kind == "environment":
        light = _environment(t, color, intensity, base_dir, allow_outside)
    elif kind == "point":
        light = Light("point", color, intensity, position=tuple(t.vector("position", 3)))
    else:
        direction = t.vector("direction", 3)
        if np.linalg.norm(direction) == 0:
            t.fail("direction", "must not be the zero vector.")
        light = Light("directional", color, intensity, direction=tuple(direction))
    t.check_unknown()
    return light


def _environment(t: _Table, color, intensity, base_dir: Path, allow_outside: bool) -> Environment:
    """``type = "environment"``: ``map`` (a linear latitude-longitude EXR, +z up) or none (a
    constant ``color``), ``rotation`` in degrees about +z."""
    rotation = t.number("rotation", 0.0)
    if not t.has("map"):
        return dataclasses.replace(Environment.constant(color, intensity), rotation=rotation)
    path = _inside(t, "map", Path(t.string("map")), base_dir, allow_outside)
    try:
        radiance = read_map(path, "map", encoded_ok=False, section=t.name)[::-1]  # read_map gives texel order
    except MapError as error:
        raise SceneError(str(error)) from None
    if np.any(radiance < 0):
        t.fail("map", f"{path}: {int((radiance < 0).sum())} negative radiance value(s); radiance is never negative.")
    peak = float(radiance.max()) * intensity * max(color)
    if peak > MAX_RADIANT:
        t.fail("intensity", f"the map's brightest pixel {float(radiance.max()):g} times intensity and colour exceeds "
                            f"{MAX_RADIANT:g}; scale the light and the exposure down together.")
    return Environment(np.ascontiguousarray(radiance), color, intensity, rotation, str(path))


def _camera(t: _Table) -> PerspectiveView:
    position = t.vector("position", 3)
    look_at = t.vector("look_at", 3, (0.0, 0.0, 0.0))
    if np.allclose(position, look_at):
        t.fail("look_at", "must differ from position.")
    fov = t.number("fov", 30.0, positive=True)
    if fov >= 180:
        t.fail("fov", f"must be below 180 degrees; got {fov}.")
    resolution = t.vector("resolution", 2, (320, 240), positive=True)
    if np.any(resolution != np.round(resolution)):
        t.fail("resolution", f"must be two integers; got {resolution.tolist()}.")
    width, height = int(resolution[0]), int(resolution[1])
    problem = budget.check_size(width * height, budget.BYTES_PER_PIXEL, f"{width} x {height} pixels",
                                largest=f"{{}} pixels, e.g. {_square(budget.available_memory() / 2 / budget.BYTES_PER_PIXEL)}")
    if problem:
        t.fail("resolution", problem)
    up = t.vector("up", 3, (0.0, 0.0, 1.0))
    view = look_at - position
    cross = np.linalg.norm(np.cross(up, view))
    if not cross > 1e-6 * np.linalg.norm(up) * np.linalg.norm(view):
        what = "is the zero vector" if not np.any(up) else f"{up.tolist()} is parallel to the view direction"
        t.fail("up", f"{what}: the camera needs an up across the view (look_at - position = {view.tolist()}); "
                     "e.g. [0, 0, 1] unless the camera looks straight up or down.")
    t.check_unknown()
    return PerspectiveView(tuple(position), tuple(look_at), fov, int(resolution[0]), int(resolution[1]), tuple(up))


def _square(count: float) -> str:
    side = int(np.sqrt(max(count, 0.0)))
    return f"{side} x {side}"


def parse_scene(data: dict, *, source: str = "<scene>", base_dir=".", allow_outside: bool = False) -> Scene:
    """Build a :class:`Scene` from a TOML-shaped dict (see the module docstring). Files the scene
    names (an OBJ, maps) must lie in ``base_dir`` unless ``allow_outside``."""
    root = _Table(data, "scene", source)
    # Unknown sections first: a misspelt [materail] must not be reported as a missing [material].
    root.check_unknown(_SECTIONS)
    mesh, base_colour, colour_source = _geometry(_Table(root.raw("geometry"), "geometry", source), Path(base_dir),
                                                 allow_outside)
    material = _material(_Table(root.raw("material"), "material", source), source, Path(base_dir), allow_outside,
                         mesh_colour=(base_colour, colour_source))
    if material.maps is not None and material.maps.files and not mesh.has_uvs:
        _Table(root.raw("material"), "material", source).fail(
            "maps", f"the mesh {mesh.name} has no UV layout (no vt lines in its file); maps are read through it.")
    entries = root.raw("lights")
    if not isinstance(entries, list) or not entries:
        root.fail("lights", "must be a non-empty array of tables ([[lights]]).")
    lights = tuple(_light(_Table(e, f"lights[{i}]", source), Path(base_dir), allow_outside)
                   for i, e in enumerate(entries))
    if sum(light.kind == "environment" for light in lights) > 1:
        root.fail("lights", "has more than one environment; merge them into one map.")
    camera = _camera(_Table(root.raw("camera"), "camera", source))
    r = _Table(root.raw("render", {}), "render", source)
    accuracy = r.number("accuracy", 0.05, positive=True)
    if accuracy >= 1:
        r.fail("accuracy", f"is a relative error and must lie in (0, 1); got {accuracy}.")
    texture_size = r.number("texture_size", 512, integer=True, positive=True)
    if texture_size < 16 or texture_size > 8192:
        r.fail("texture_size", f"must lie in [16, 8192]; got {texture_size}.")
    problem = budget.check_size(texture_size**2, budget.BYTES_PER_TEXEL, f"a {texture_size}^2 texture",
                                largest=f"{{}} texels, {_square(budget.available_memory() / 2 / budget.BYTES_PER_TEXEL)}")
    if problem:
        r.fail("texture_size", problem)
    shadow = r.number("shadow_map_size", 512, integer=True, positive=True)
    problem = budget.check_size(len(lights) * shadow**2, budget.BYTES_PER_SHADOW_TEXEL,
                                f"{len(lights)} shadow map(s) of {shadow}^2",
                                largest=f"{{}} texels, {_square(budget.available_memory() / 2 / budget.BYTES_PER_SHADOW_TEXEL / len(lights))} each")
    if problem:
        r.fail("shadow_map_size", problem)
    exposure = r.number("exposure", None, positive=True)
    method = r.string("method", None, "auto")
    if method != "auto":
        try:
            method = Method(method).value
        except ValueError:
            r.fail("method", f"must be auto, {', '.join(m.value for m in Method)}; got {method!r}.")
    r.check_unknown()
    root.check_unknown()
    return Scene(mesh, material, lights, camera, 0.05, texture_size, shadow, exposure, source,
                 method=None if method == "auto" else method).with_accuracy(accuracy)


def load_scene(path, *, allow_outside: bool = False) -> Scene:
    """Read a TOML scene file; relative OBJ and map paths are resolved next to it, and must stay
    in its folder unless ``allow_outside``."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise SceneError(f"{path}: no such scene file.") from None
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: not valid TOML ({error}).") from None
    except UnicodeDecodeError as error:  # TOML is UTF-8; a binary file or UTF-16 is not
        raise SceneError(f"{path}: not a TOML scene: byte {error.start} is not UTF-8 ({error.reason}).") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a folder, not a scene file.") from None
    return parse_scene(data, source=str(path), base_dir=path.parent, allow_outside=allow_outside)
