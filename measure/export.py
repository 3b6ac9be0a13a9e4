r"""A medium for the renderers people use: Mitsuba 3, pbrt-v4 and Blender Cycles.

Each exporter takes a :class:`jsss.Medium` (sigma_a and reduced scattering sigma_s' in 1/mm,
one value per colour channel, R, G, B) and the Henyey-Greenstein ``g`` the user knows, and
returns text or plain Python data; writing files is the caller's (``fit-params --export``).

Units
-----
jsss works in mm. A renderer's scene unit is ``unit_mm`` millimetres (1 for a scene modelled
in mm, 10 in cm, 1000 in metres); coefficients in 1/(scene unit) are the ones in 1/mm times
``unit_mm`` and lengths in scene units are mm / ``unit_mm``.

Reduced and real scattering
---------------------------
A fit determines sigma_s' = sigma_s (1 - g), not sigma_s: light far from its entry point only
sees the reduced coefficient (similarity). The path tracers below take the real sigma_s and
the phase function, so they get ``sigma_s = sigma_s' / (1 - g)`` with the given ``g``
(``g = 0``, the default, makes them equal). Near the entry point (within a few mean free
paths) a renderer given another ``g`` than the material's differs from the measurement;
nothing in a beam-profile fit can tell g.

What each drops
---------------
Measured in ``docs/benchmarks/exports.md`` (``benchmarks/exports.py``: a thick slab of marble,
ketchup and skin1 in a white environment, against F(0) + (1 - F(0)) R_d of the transport
tables): Mitsuba within 0.5 %, Cycles within 0.2 % in all nine channels.

- All three: layers (a homogeneous medium only: export a stack's effective medium, which
  keeps its total but not its profile), the surface's specular roughness, and the
  Fresnel-weighted glint the camera saw (none is fitted from a beam profile).
- Mitsuba 3 (``homogeneous`` medium inside a ``dielectric``): nothing of the medium, g
  included; use the ``volpathmis`` integrator for media whose extinction differs between
  channels (plain ``volpath`` samples distances with one channel's extinction, and the weight
  of a channel with lower extinction has infinite variance: see
  ``benchmarks/transport_truth.py``), and keep its Russian roulette away from the light that
  matters (``rr_depth`` 10^4: from depth 1000 it returned marble 0.9 % too dark).
- pbrt-v4 (``subsurface`` material): pbrt evaluates photon beam diffusion from sigma_a,
  sigma_s, g and eta, a diffusion model with its own near-source error (not rendered here).
- Blender Cycles (Principled BSDF, random-walk subsurface, roughness 0): Cycles'
  walk has no internal Fresnel reflection, stops at 256 bounces, raises albedos below 0.2
  and turns isotropic after 9 bounces (:mod:`measure.cycles_walk`). The export gives it the
  medium's mean free path and a colour that makes its walk return the medium's *total*
  reflectance (:func:`blender_principled`), so a thick piece is as bright as the medium;
  it drops the profile's shape (Cycles' albedo is not the medium's: light spreads
  differently, and thin parts and edges differ) and g beyond Cycles' own walk (with
  g = 0.8 the total is within 2 % except skin's red, 3.5 % bright).

Colour maps
-----------
A fitted colour map c (``jsss-render fit --albedo-map``: pre-post texturing, d'Eon et al.
2007 sec. 5.3, M(x) = sqrt(c(x)) int R sqrt(c(y)) E(y) dA_y, c relative to the medium) goes
to each renderer as a texture beside the homogeneous medium, in the map file's layout (its
bottom row is v = 0, OBJ's convention, which Mitsuba's OBJ loader and Blender's image
textures follow; :func:`jsss.render.surface_maps.read_map`):

- Mitsuba 3: the ``dielectric``'s ``specular_transmittance`` is sqrt(c)
  (:func:`prepost_transmittance`). Each crossing of the boundary, in or out, multiplies the
  path by the texture at that point, and reflection (outside or inside) keeps its weight:
  exactly pre-post's sqrt(c) in and sqrt(c) out, the medium's internal reflection untouched.
  Values above 1 (the map brighter than the medium) are multiplied as they are.
- Blender Cycles: an Image Texture into Base Color, per texel the colour whose walk returns
  c R_d (:func:`blender_colour_map`). Cycles reads the colour where the camera path enters,
  the point the camera sees: post-scatter texturing, so the map's edges stay sharper than
  jsss's pre-post blur of them.
- pbrt-v4: none (its ``subsurface`` material is written with constant coefficients).
"""

from __future__ import annotations

import warnings

import numpy as np

from . import cycles_walk

__all__ = ["blender_colour_map", "blender_principled", "blender_python", "cycles_albedo_from_colour",
           "cycles_colour_from_albedo", "mitsuba_dict", "mitsuba_xml", "pbrt_material", "prepost_transmittance",
           "scattering_coefficients"]


def scattering_coefficients(medium, *, g=0.0, unit_mm=1.0):
    """sigma_a, the real sigma_s and the single eta of ``medium`` in 1/(scene unit).

    Returns
    -------
    sigma_a, sigma_s : (C,) float arrays, 1/(scene unit); ``sigma_s = sigma_s' / (1 - g)``.
    eta : float, the relative index (one value: the renderers take a scalar index).

    Raises
    ------
    ValueError
        ``g`` outside (-1, 1), ``unit_mm <= 0``, or an eta that differs between channels.
    """
    g = float(g)
    if not -1.0 < g < 1.0:
        raise ValueError(f"g must lie in (-1, 1) (Henyey-Greenstein mean cosine); got {g:g}.")
    unit_mm = _check_unit(unit_mm)
    sigma_a = np.atleast_1d(np.asarray(medium.sigma_a, dtype=float))
    sigma_s_prime = np.atleast_1d(np.asarray(medium.sigma_s_prime, dtype=float))
    sigma_a, sigma_s_prime = np.broadcast_arrays(sigma_a, sigma_s_prime)
    eta = np.atleast_1d(np.asarray(medium.eta, dtype=float))
    if np.ptp(eta) > 1e-9:
        raise ValueError(f"the renderers take one index of refraction; this medium has eta = {eta.tolist()} per channel.")
    return sigma_a * unit_mm, sigma_s_prime / (1.0 - g) * unit_mm, float(eta[0])


def _check_unit(unit_mm) -> float:
    unit_mm = float(unit_mm)
    if not (np.isfinite(unit_mm) and unit_mm > 0):
        raise ValueError(f"unit_mm must be > 0 (millimetres per scene unit: 1 for mm, 1000 for metres); got {unit_mm:g}.")
    return unit_mm


def _rgb(values) -> list[float]:
    values = [float(v) for v in np.ravel(values)]
    if len(values) == 1:
        values = values * 3
    if len(values) != 3:
        raise ValueError(f"the exporters write RGB materials: 1 or 3 channels; got {len(values)}.")
    return values


def _fmt(values) -> str:
    return " ".join(f"{v:.9g}" for v in values)


# ----------------------------------------------------------------------------- Mitsuba 3
def mitsuba_dict(medium, *, g=0.0, unit_mm=1.0, transmittance=None):
    """The material as Mitsuba 3 scene-dict entries: ``{"bsdf": ..., "interior": ...}``.

    Put both on a closed shape: ``{"type": "ply", ..., "bsdf": d["bsdf"], "interior": d["interior"]}``.
    The medium is ``homogeneous`` with ``sigma_t = sigma_a + sigma_s`` (as ``scale`` times an
    RGB of at most 1), ``albedo = sigma_s / sigma_t`` and a Henyey-Greenstein phase function;
    the boundary a smooth ``dielectric`` of the medium's eta against air. ``transmittance``, the
    name of an image of :func:`prepost_transmittance` (a colour map's sqrt), becomes the
    dielectric's ``specular_transmittance`` (``bitmap``, raw values, bilinear, clamped at the
    border as jsss's maps are; see the module's "Colour maps").
    """
    sigma_a, sigma_s, eta = scattering_coefficients(medium, g=g, unit_mm=unit_mm)
    sigma_t = np.asarray(_rgb(sigma_a + sigma_s))
    scale = float(sigma_t.max())
    if not scale > 0:
        raise ValueError("the medium has no extinction (sigma_a = sigma_s' = 0): nothing to export.")
    albedo = np.asarray(_rgb(sigma_s)) / np.where(sigma_t > 0, sigma_t, 1.0)
    interior = {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": (sigma_t / scale).tolist()},
                "albedo": {"type": "rgb", "value": albedo.tolist()}, "scale": scale,
                "phase": {"type": "hg", "g": float(g)}}
    bsdf = {"type": "dielectric", "int_ior": eta, "ext_ior": 1.0}
    if transmittance is not None:
        bsdf["specular_transmittance"] = {"type": "bitmap", "filename": str(transmittance), "raw": True,
                                          "filter_type": "bilinear", "wrap_mode": "clamp"}
    return {"bsdf": bsdf, "interior": interior}


def prepost_transmittance(albedo_map):
    r"""The Mitsuba texture of a pre-post colour map: :math:`t = \sqrt{c}` per texel and channel.

    A path that enters at y and leaves at x through a ``dielectric`` whose
    ``specular_transmittance`` is t carries :math:`t(y)\,t(x) = \sqrt{c(y)}\sqrt{c(x)}`, the
    pre-post map's weight. ``albedo_map``: (rows, columns, 3), finite and >= 0 (``ValueError``
    otherwise); the result has its layout (write it as the map file is written).
    """
    return np.sqrt(_colour_map(albedo_map))


def _colour_map(albedo_map) -> np.ndarray:
    """``albedo_map`` as a float array, checked: (rows, columns, 3), finite and >= 0 (ValueError)."""
    albedo_map = np.asarray(albedo_map, float)
    if albedo_map.ndim != 3 or albedo_map.shape[-1] != 3:
        raise ValueError(f"a colour map is (rows, columns, 3); got shape {albedo_map.shape}")
    if not np.all(np.isfinite(albedo_map) & (albedo_map >= 0)):
        raise ValueError("a colour map's values must be finite and >= 0")
    return albedo_map


def mitsuba_xml(medium, *, g=0.0, unit_mm=1.0, name="jsss", preview=True, transmittance=None):
    """The material as Mitsuba 3 XML: a ``dielectric`` BSDF and a ``homogeneous`` medium.

    With ``preview`` (default) the file is a whole scene that ``mitsuba file.xml`` renders: a
    sphere of radius 20 mm (in scene units) with the material, in a white furnace (constant
    environment of radiance 1), seen by a 64 x 64 camera, integrator ``volpathmis``. Without
    it, only the two declarations to paste into a scene; a shape uses them with
    ``<ref id="NAME_bsdf"/>`` and ``<ref name="interior" id="NAME_medium"/>``.

    ``transmittance``: the file name (relative to the XML, as Mitsuba resolves it) of a colour
    map's :func:`prepost_transmittance`, written in the map file's layout (bottom row v = 0);
    the dielectric's ``specular_transmittance``. It lies right on an OBJ mesh with UVs (Mitsuba's
    OBJ loader flips v to that layout). Mitsuba's built-in sphere puts v = 0 (its +z pole, as
    jsss's sphere does) on the image's top row, so the preview's texture flips v (``to_uv``);
    the declarations alone do not. The texture's values are raw (above 1 where the map is),
    which Mitsuba's RGB variants render and its spectral ones refuse.
    """
    d = mitsuba_dict(medium, g=g, unit_mm=unit_mm, transmittance=transmittance)
    m, b, ident = d["interior"], d["bsdf"], _xml_attribute(name)
    texture = ""
    if transmittance is not None:  # mitsuba_dict's bitmap, written out
        t = b["specular_transmittance"]
        flip = ('            <transform name="to_uv">\n'
                '                <scale x="1" y="-1"/>\n'
                '                <translate x="0" y="1"/>\n'
                '            </transform>\n') if preview else ""
        texture = ('        <texture type="bitmap" name="specular_transmittance">\n'
                   f'            <string name="filename" value="{_xml_attribute(t["filename"])}"/>\n'
                   f'            <boolean name="raw" value="{str(t["raw"]).lower()}"/>\n'
                   f'            <string name="filter_type" value="{t["filter_type"]}"/>\n'
                   f'            <string name="wrap_mode" value="{t["wrap_mode"]}"/>\n'
                   + flip + '        </texture>\n')

    declarations = (
        f'    <bsdf type="dielectric" id="{ident}_bsdf">\n'
        f'        <float name="int_ior" value="{b["int_ior"]:.9g}"/>\n'
        f'        <float name="ext_ior" value="1"/>\n'
        + texture +
        f'    </bsdf>\n'
        f'    <medium type="homogeneous" id="{ident}_medium">\n'
        f'        <rgb name="sigma_t" value="{", ".join(f"{v:.9g}" for v in m["sigma_t"]["value"])}"/>\n'
        f'        <rgb name="albedo" value="{", ".join(f"{v:.9g}" for v in m["albedo"]["value"])}"/>\n'
        f'        <float name="scale" value="{m["scale"]:.9g}"/>\n'
        f'        <phase type="hg">\n'
        f'            <float name="g" value="{float(g):.9g}"/>\n'
        f'        </phase>\n'
        f'    </medium>\n')
    header = (f"<!-- jsss: sigma_a, sigma_s in 1/(scene unit), scene unit = {float(unit_mm):g} mm; "
              f"sigma_s = sigma_s' / (1 - g), g = {float(g):g} -->\n")
    if transmittance is not None:
        header += ("<!-- jsss: a pre-post colour map c: the dielectric's specular_transmittance is sqrt(c) in the map "
                   "file's layout (OBJ's: bottom row v = 0), raw values, so an RGB variant (scalar_rgb, llvm_ad_rgb, "
                   "cuda_ad_rgb) renders it"
                   + (". The preview's built-in sphere needs its v flipped (to_uv): remove the to_uv block when "
                      "this bsdf goes on an OBJ mesh" if preview else "") + ". -->\n")
    if not preview:
        return header + '<scene version="3.0.0">\n' + declarations + "</scene>\n"
    radius = 20.0 / float(unit_mm)
    return header + (
        '<scene version="3.0.0">\n'
        '    <integrator type="volpathmis">\n'
        '        <integer name="max_depth" value="-1"/>\n'
        '        <integer name="rr_depth" value="10000"/>\n'
        '    </integrator>\n'
        + declarations +
        f'    <shape type="sphere">\n'
        f'        <float name="radius" value="{radius:.9g}"/>\n'
        f'        <ref id="{ident}_bsdf"/>\n'
        f'        <ref name="interior" id="{ident}_medium"/>\n'
        f'    </shape>\n'
        '    <emitter type="constant">\n'
        '        <rgb name="radiance" value="1, 1, 1"/>\n'
        '    </emitter>\n'
        '    <sensor type="perspective">\n'
        '        <float name="fov" value="30"/>\n'
        '        <transform name="to_world">\n'
        f'            <lookat origin="0, {-5 * radius:.9g}, 0" target="0, 0, 0" up="0, 0, 1"/>\n'
        '        </transform>\n'
        '        <film type="hdrfilm">\n'
        '            <integer name="width" value="64"/>\n'
        '            <integer name="height" value="64"/>\n'
        '        </film>\n'
        '    </sensor>\n'
        '</scene>\n')


def _xml_attribute(text) -> str:
    """``text`` safe inside a double-quoted XML attribute."""
    from xml.sax.saxutils import escape

    return escape(str(text), {'"': "&quot;"})


# ----------------------------------------------------------------------------- pbrt-v4
def pbrt_material(medium, *, g=0.0, unit_mm=1.0, name="jsss"):
    """A pbrt-v4 ``MakeNamedMaterial`` of type ``subsurface``.

    sigma_a and sigma_s are written in 1/mm with ``scale = unit_mm`` (pbrt multiplies both by
    ``scale``), so the numbers stay the fitted ones; use it with ``NamedMaterial "NAME"``.
    """
    unit_mm = _check_unit(unit_mm)
    sigma_a, sigma_s, eta = scattering_coefficients(medium, g=g, unit_mm=1.0)
    return (f"# jsss: sigma in 1/mm, scale = {float(unit_mm):g} mm per scene unit; sigma_s = sigma_s' / (1 - g)\n"
            f'MakeNamedMaterial "{str(name).replace(chr(34), "_")}"\n'
            f'    "string type" [ "subsurface" ]\n'
            f'    "rgb sigma_a" [ {_fmt(_rgb(sigma_a))} ]\n'
            f'    "rgb sigma_s" [ {_fmt(_rgb(sigma_s))} ]\n'
            f'    "float scale" [ {float(unit_mm):.9g} ]\n'
            f'    "float eta" [ {eta:.9g} ]\n'
            f'    "float g" [ {float(g):.9g} ]\n')


# ----------------------------------------------------------------------------- Blender Cycles
cycles_albedo_from_colour = cycles_walk.albedo_from_colour
cycles_colour_from_albedo = cycles_walk.colour_from_albedo


CYCLES_RADIUS_SCALE = 4 * np.pi  # Cycles multiplies a random walk's radius by 0.25 / pi (bssrdf_setup_radius)


def blender_principled(medium, *, g=0.0, unit_mm=1.0):
    r"""Principled BSDF inputs for Cycles' random-walk subsurface scattering.

    **Radius: the medium's mean free path.** Cycles first scales the radius R (``Subsurface
    Radius`` x ``Subsurface Scale``, scene units) by :math:`1/4\pi` "so it gives similar looking
    result to older Cubic, Gaussian and Burley models" (``bssrdf_setup_radius`` in
    ``kernel/closure/bssrdf.h``, read in the sources the bpy 4.5.15 wheel ships), then turns
    the colour A and :math:`d = R / 4\pi` into :math:`\sigma_t = 1 / (d (1 - g))` and a
    single-scattering albedo :math:`\alpha_c = f_g(A)` (``subsurface_random_walk.h``). So

    .. math::

        R = \frac{4\pi}{(1 - g)\,\sigma_t} = \frac{4\pi}{(1 - g)\,\sigma_a + \sigma_s'}

    (with g = 0, 4 pi transport mean free paths) gives Cycles the medium's extinction.

    **Colour: the medium's total reflectance.** Cycles' walk is not the medium's: it has no
    internal Fresnel reflection, stops at 256 bounces and raises albedos below 0.2
    (:mod:`measure.cycles_walk`). Given the medium's own albedo it renders marble 4 % and
    skin 10-20 % too bright. The colour is chosen instead so that Cycles' walk returns the
    medium's total diffuse reflectance :math:`R_d` (per unit entering flux, exact to transport:
    :func:`jsss.transport.total_reflectance` at the medium's eta and g):

    .. math::

        A = f_g^{-1}(\alpha_c), \qquad R_c(\alpha_c) = R_d(\eta),

    with :math:`R_c` the model of Cycles' walk (:func:`measure.cycles_walk.walk_reflectance`).
    A flat, thick piece then looks right in Cycles under any smooth lighting: at normal view
    in a white environment it shows :math:`F(0) + (1 - F(0)) R_d`, as the medium does
    (``benchmarks/exports.py`` measures within 1 % for marble, ketchup, skin1). What it
    cannot match: the profile's shape (how far light spreads, thin parts, edges), since
    :math:`\alpha_c` differs from the medium's :math:`\sigma_s/\sigma_t` and only the total
    and the mean free path agree. Where the tables do not hold the medium's g, :math:`R_d`
    is the g = 0 table's (similarity); outside their eta range (1.0-1.6), the nearest eta's
    (a warning says so).

    (Until 2026-12-04 the export left out the 4 pi, +4 to +123 % bright against F0 + T0 R_d;
    a half-shadow edge and a 1 mm slab over black measured a best-fit scale of 12.75; and it
    gave A for the medium's own albedo.)

    Returns
    -------
    dict with ``base_color`` (3 floats), ``subsurface_radius`` (3 floats, scene units,
    with ``subsurface_scale = 1``), ``subsurface_scale``, ``subsurface_anisotropy`` (g),
    ``ior`` (eta), ``roughness`` (0: the smooth surface jsss models), ``subsurface_weight``
    (1), ``subsurface_method`` ("RANDOM_WALK") and ``total_reflectance`` (the :math:`R_d`
    matched, 3 floats).
    """
    sigma_a, sigma_s, eta = scattering_coefficients(medium, g=g, unit_mm=unit_mm)
    sigma_t = np.asarray(_rgb(sigma_a + sigma_s))
    if not np.all(sigma_t > 0):
        raise ValueError("a channel without extinction (sigma_a = sigma_s' = 0) has no Cycles radius.")
    target = _total_reflectance(medium, float(g), eta)
    alpha, reachable = cycles_walk.albedo_for_reflectance(target, g)
    if not np.all(reachable):
        warnings.warn(f"total reflectance {target.max():.4f} is above the {cycles_walk.walk_reflectance(1.0, g):.4f} "
                      "that Cycles' walk returns at its largest albedo (its 256-bounce cap loses the rest); "
                      "the colour is clamped there (a darker material)", stacklevel=2)
    colour = cycles_colour_from_albedo(alpha, g)
    radius = CYCLES_RADIUS_SCALE / ((1.0 - float(g)) * sigma_t)
    return {"base_color": colour.tolist(), "subsurface_radius": radius.tolist(), "subsurface_scale": 1.0,
            "subsurface_anisotropy": float(g), "ior": eta, "roughness": 0.0, "subsurface_weight": 1.0,
            "subsurface_method": "RANDOM_WALK", "total_reflectance": target.tolist()}


def _total_reflectance(medium, g, eta):
    """R_d per unit entering flux from the transport tables (3 channels), at the nearest
    tabulated eta and with g = 0 where g is not tabulated (similarity)."""
    from jsss import Medium, transport

    info = transport.table_info()
    low, high = float(info["etas"][0]), float(info["etas"][-1])
    if not low <= eta <= high:
        warnings.warn(f"eta {eta:g} is outside the transport tables ({low:g}-{high:g}); Cycles' colour matches "
                      f"the total reflectance at eta {min(max(eta, low), high):g}", stacklevel=3)
    if not np.any(np.isclose(info["gs"], g, atol=1e-9)):
        g = 0.0
    sigma_a = np.asarray(_rgb(medium.sigma_a), float)
    sigma_s_prime = np.asarray(_rgb(medium.sigma_s_prime), float)
    # Below the tables' reduced albedo 0.001 (a clear liquid's channel, sigma_s' = 0 included)
    # light returns after one scattering: R_d is proportional to the albedo, from the last node.
    last = float(info["absorption"][-1]) * (1 - 1e-6)  # the last node, inside it in float32 too
    reduced, floor = sigma_s_prime / (sigma_a + sigma_s_prime), 1.0 / (1.0 + last)
    clear = reduced < floor
    tabulated = Medium(np.where(clear, last, sigma_a), np.where(clear, 1.0, sigma_s_prime), min(max(eta, low), high))
    total = np.asarray(transport.total_reflectance(tabulated, g=g), float)
    return np.where(clear, total * reduced / floor, total)


def blender_colour_map(medium, albedo_map, *, g=0.0):
    r"""Cycles' Base Color per texel of a pre-post colour map ``albedo_map`` (rows, columns, 3).

    Each texel's colour is the one whose walk returns :math:`c\,R_d`, the medium's total
    reflectance (:func:`blender_principled`) times the map, so a thick piece painted with the
    map is as bright in Cycles, texel by texel, as jsss renders it far from the map's edges.
    Cycles reads the colour where the camera sees the surface (post-scatter texturing), not
    sqrt(c) at both ends. A total beyond Cycles' walk is clamped with a warning. The result
    has the map's layout.
    """
    albedo_map = _colour_map(albedo_map)
    _, _, eta = scattering_coefficients(medium, g=g)
    target = albedo_map * _total_reflectance(medium, float(g), eta)
    alpha, reachable = cycles_walk.albedo_for_reflectance(target, g)
    if not np.all(reachable):
        warnings.warn(f"{np.count_nonzero(~reachable)} texel channels of the map ask for a total reflectance above "
                      f"the {cycles_walk.walk_reflectance(1.0, g):.4f} that Cycles' walk returns at its largest "
                      "albedo; their colour is clamped there (darker)", stacklevel=2)
    return cycles_colour_from_albedo(alpha, g)


def blender_python(medium, *, g=0.0, unit_mm=1.0, name="jsss", colour_map=None):
    """A Python script for Blender (4.x) that creates material NAME with :func:`blender_principled`'s inputs.

    Run it in Blender's text editor or ``blender --python FILE``; it assigns the material to
    the active object when there is one. ``colour_map``: the path of an image of
    :func:`blender_colour_map` (in the map file's layout, which Blender's image textures share);
    the script reads it from the folder it was exported to, else beside the script, the .blend
    or the working folder, into Base Color through an Image Texture node (linear, non-colour
    data, bilinear, clamped at the border) on the object's active UV map.
    """
    p = blender_principled(medium, g=g, unit_mm=unit_mm)
    rd = ", ".join(f"{v:.4f}" for v in p["total_reflectance"])
    return (f"# jsss: Cycles random-walk subsurface; radius in scene units of {float(unit_mm):g} mm; "
            f"g = {float(g):g}, eta = {p['ior']:.6g}\n"
            "# Radius: 4 pi mean free paths (Cycles divides it by 4 pi): Cycles' extinction is the medium's.\n"
            "# Base Color: chosen so that Cycles' walk (no internal reflection, 256 bounces at most, albedo\n"
            "# >= 0.2) returns the medium's total diffuse reflectance, not for the medium's albedo:\n"
            f"# R_d = ({rd}). A thick piece's brightness is right; the profile's shape (spread,\n"
            "# thin parts, edges) is Cycles' own. Dropped: layers, g beyond Cycles' walk (isotropic after\n"
            "# 9 bounces). Keep Roughness 0 and Specular IOR Level 0.5: the colour assumes that surface.\n"
            "import bpy\n"
            f"material = bpy.data.materials.new({name!r})\n"
            "material.use_nodes = True\n"
            "node = material.node_tree.nodes['Principled BSDF']\n"
            "node.subsurface_method = 'RANDOM_WALK'\n"
            f"node.inputs['Base Color'].default_value = ({_fmt(p['base_color']).replace(' ', ', ')}, 1.0)\n"
            "node.inputs['Subsurface Weight'].default_value = 1.0\n"
            f"node.inputs['Subsurface Radius'].default_value = ({_fmt(p['subsurface_radius']).replace(' ', ', ')})\n"
            "node.inputs['Subsurface Scale'].default_value = 1.0\n"
            f"node.inputs['Subsurface Anisotropy'].default_value = {p['subsurface_anisotropy']:.9g}\n"
            f"node.inputs['IOR'].default_value = {p['ior']:.9g}\n"
            "node.inputs['Roughness'].default_value = 0.0  # the smooth surface the colour was chosen for\n"
            + ("" if colour_map is None else _blender_texture(colour_map)) +
            "if bpy.context.active_object is not None:\n"
            "    bpy.context.active_object.active_material = material\n")


def _blender_texture(colour_map) -> str:
    """The script's lines that read ``colour_map`` into Base Color: from the folder it was exported
    to, else beside the script (``blender --python``), the .blend or the working folder (Blender's
    text editor names no folder of its own), or one line that says where it looked."""
    import os

    name, folder = os.path.basename(str(colour_map)), os.path.dirname(os.path.abspath(str(colour_map)))
    return ("# The colour map: per texel the Base Color whose walk returns c R_d (c: the fitted map). Cycles\n"
            "# reads it where the camera sees the surface (post-scatter), not sqrt(c) at both ends (jsss).\n"
            "import os\n"
            f"colour_map = {name!r}\n"
            f"folders = [{folder!r}, os.path.dirname(os.path.abspath(__file__)) if '__file__' in globals() else '',\n"
            "           bpy.path.abspath('//'), os.getcwd()]\n"
            "found = [os.path.join(f, colour_map) for f in folders if f and os.path.isfile(os.path.join(f, colour_map))]\n"
            "if not found:\n"
            "    raise FileNotFoundError(f'{colour_map}: the colour map is in none of {folders}; put it beside this '\n"
            "                            'script or the .blend')\n"
            "texture = material.node_tree.nodes.new('ShaderNodeTexImage')\n"
            "texture.image = bpy.data.images.load(found[0])\n"
            "texture.image.colorspace_settings.name = 'Non-Color'  # linear values, used as they are\n"
            "texture.interpolation = 'Linear'\n"
            "texture.extension = 'EXTEND'  # clamped at the border, as jsss's maps are\n"
            "material.node_tree.links.new(texture.outputs['Color'], node.inputs['Base Color'])\n")
