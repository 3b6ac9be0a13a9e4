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
- All three: layers (a homogeneous medium only), the surface's specular roughness, and the
  Fresnel-weighted glint the camera saw (none is fitted from a beam profile).
- Mitsuba 3 (``homogeneous`` medium inside a ``dielectric``): nothing of the medium; use the
  ``volpathmis`` integrator for media whose extinction differs between channels (plain
  ``volpath`` samples distances with one channel's extinction, and the weight of a channel
  with lower extinction has infinite variance: see ``benchmarks/transport_truth.py``).
- pbrt-v4 (``subsurface`` material): pbrt evaluates photon beam diffusion from sigma_a,
  sigma_s, g and eta, a diffusion model with its own near-source error.
- Blender Cycles (Principled BSDF, random-walk subsurface): Cycles parameterises the medium
  by a colour A and a radius d (:func:`blender_principled`); single-scattering albedos below
  0.2 are raised to 0.2 by Cycles with the throughput scaled down to compensate (ketchup's
  green and blue), and after 9 bounces it switches to the similar isotropic medium.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["blender_principled", "blender_python", "cycles_albedo_from_colour", "cycles_colour_from_albedo",
           "mitsuba_dict", "mitsuba_xml", "pbrt_material", "scattering_coefficients"]


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
def mitsuba_dict(medium, *, g=0.0, unit_mm=1.0):
    """The material as Mitsuba 3 scene-dict entries: ``{"bsdf": ..., "interior": ...}``.

    Put both on a closed shape: ``{"type": "ply", ..., "bsdf": d["bsdf"], "interior": d["interior"]}``.
    The medium is ``homogeneous`` with ``sigma_t = sigma_a + sigma_s`` (as ``scale`` times an
    RGB of at most 1), ``albedo = sigma_s / sigma_t`` and a Henyey-Greenstein phase function;
    the boundary a smooth ``dielectric`` of the medium's eta against air.
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
    return {"bsdf": bsdf, "interior": interior}


def mitsuba_xml(medium, *, g=0.0, unit_mm=1.0, name="jsss", preview=True):
    """The material as Mitsuba 3 XML: a ``dielectric`` BSDF and a ``homogeneous`` medium.

    With ``preview`` (default) the file is a whole scene that ``mitsuba file.xml`` renders: a
    sphere of radius 20 mm (in scene units) with the material, in a white furnace (constant
    environment of radiance 1), seen by a 64 x 64 camera, integrator ``volpathmis``. Without
    it, only the two declarations to paste into a scene; a shape uses them with
    ``<ref id="NAME_bsdf"/>`` and ``<ref name="interior" id="NAME_medium"/>``.
    """
    d = mitsuba_dict(medium, g=g, unit_mm=unit_mm)
    m, b = d["interior"], d["bsdf"]
    declarations = (
        f'    <bsdf type="dielectric" id="{name}_bsdf">\n'
        f'        <float name="int_ior" value="{b["int_ior"]:.9g}"/>\n'
        f'        <float name="ext_ior" value="1"/>\n'
        f'    </bsdf>\n'
        f'    <medium type="homogeneous" id="{name}_medium">\n'
        f'        <rgb name="sigma_t" value="{", ".join(f"{v:.9g}" for v in m["sigma_t"]["value"])}"/>\n'
        f'        <rgb name="albedo" value="{", ".join(f"{v:.9g}" for v in m["albedo"]["value"])}"/>\n'
        f'        <float name="scale" value="{m["scale"]:.9g}"/>\n'
        f'        <phase type="hg">\n'
        f'            <float name="g" value="{float(g):.9g}"/>\n'
        f'        </phase>\n'
        f'    </medium>\n')
    header = (f"<!-- jsss: sigma_a, sigma_s in 1/(scene unit), scene unit = {float(unit_mm):g} mm; "
              f"sigma_s = sigma_s' / (1 - g), g = {float(g):g} -->\n")
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
        f'        <ref id="{name}_bsdf"/>\n'
        f'        <ref name="interior" id="{name}_medium"/>\n'
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


# ----------------------------------------------------------------------------- pbrt-v4
def pbrt_material(medium, *, g=0.0, unit_mm=1.0, name="jsss"):
    """A pbrt-v4 ``MakeNamedMaterial`` of type ``subsurface``.

    sigma_a and sigma_s are written in 1/mm with ``scale = unit_mm`` (pbrt multiplies both by
    ``scale``), so the numbers stay the fitted ones; use it with ``NamedMaterial "NAME"``.
    """
    unit_mm = _check_unit(unit_mm)
    sigma_a, sigma_s, eta = scattering_coefficients(medium, g=g, unit_mm=1.0)
    return (f"# jsss: sigma in 1/mm, scale = {float(unit_mm):g} mm per scene unit; sigma_s = sigma_s' / (1 - g)\n"
            f'MakeNamedMaterial "{name}"\n'
            f'    "string type" [ "subsurface" ]\n'
            f'    "rgb sigma_a" [ {_fmt(_rgb(sigma_a))} ]\n'
            f'    "rgb sigma_s" [ {_fmt(_rgb(sigma_s))} ]\n'
            f'    "float scale" [ {float(unit_mm):.9g} ]\n'
            f'    "float eta" [ {eta:.9g} ]\n'
            f'    "float g" [ {float(g):.9g} ]\n')


# ----------------------------------------------------------------------------- Blender Cycles
def _cycles_fit_terms(g):
    """Cycles' fit (``subsurface_random_walk_remap``, after Chiang et al. 2016 and Wrenninge
    et al. for g) of single-scattering albedo against its colour A: six terms in g."""
    p = g ** np.arange(8)
    a = p @ [1.8260523782, -1.28451056436, -1.79904629312, 9.19393289202, -22.8215585862, 32.0234874259,
             -23.6264803333, 7.21067002658]
    b = 4.98511194385 + 0.127355959438 * np.exp(p[1:] @ [31.1491581433, -201.847017512, 841.576016723,
                                                         -2018.09288505, 2731.71560286, -1935.41424244, 559.009054474])
    c = p @ [1.09686102424, -0.394704063468, 1.05258115941, -8.83963712726, 28.8643230661, -46.8802913581,
             38.5402837518, -12.7181042538]
    d = p @ [0.496310210422, 0.360146581622, -2.15139309747, 17.8896899217, -55.2984010333, 82.065982243,
             -58.5106008578, 15.8478295021]
    e = 4.23190299701 + 0.00310603949088 * np.exp(p[1:] @ [76.7316253952, -594.356773233, 2448.8834203,
                                                           -5576.68528998, 7116.60171912, -4763.54467887, 1303.5318055])
    f = p @ [2.40602999408, -2.51814844609, 9.18494908356, -79.2191708682, 259.082868209, -403.613804597,
             302.85712436, -87.4370473567]
    return a, b, c, d, e, f


def cycles_albedo_from_colour(colour, g=0.0):
    """Cycles' single-scattering albedo for a random-walk colour A in [0, 1] (its forward map)."""
    a, b, c, d, e, f = _cycles_fit_terms(float(g))
    colour = np.clip(np.asarray(colour, dtype=float), 0.0, 1.0)
    blend = colour ** 0.25
    alpha = (1 - blend) * a * np.arctan(b * colour) ** c + blend * d * np.arctan(e * colour) ** f
    return np.clip(alpha, 0.0, 0.999999)


def cycles_colour_from_albedo(alpha, g=0.0):
    """The colour A that Cycles maps to single-scattering albedo ``alpha`` (bisection, 1e-12).

    The forward map rises from 0 at A = 0 to Cycles' clamp 0.999999 (reached at A = 0.918 for
    g = 0, lower for larger g); an albedo at the clamp gives the smallest A that reaches it.
    """
    alpha = np.asarray(alpha, dtype=float)
    lo, hi = np.zeros_like(alpha), np.ones_like(alpha)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = cycles_albedo_from_colour(mid, g) < alpha
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return hi


CYCLES_RADIUS_SCALE = 4 * np.pi  # Cycles multiplies a random walk's radius by 0.25 / pi (bssrdf_setup_radius)


def blender_principled(medium, *, g=0.0, unit_mm=1.0):
    r"""Principled BSDF inputs for Cycles' random-walk subsurface scattering.

    Cycles first scales the radius R (``Subsurface Radius`` x ``Subsurface Scale``, scene
    units) by :math:`1/4\pi` "so it gives similar looking result to older Cubic, Gaussian and
    Burley models" (``bssrdf_setup_radius`` in ``kernel/closure/bssrdf.h``, read in the sources
    the bpy 4.5.15 wheel ships), then turns the colour A and :math:`d = R / 4\pi` into
    :math:`\sigma_t = 1 / (d (1 - g))` and a single-scattering albedo :math:`\alpha = f_g(A)`
    (``kernel/integrator/subsurface_random_walk.h``). Inverting that for our medium, with
    :math:`\sigma_s = \sigma_s' / (1 - g)` and :math:`\sigma_t = \sigma_a + \sigma_s`:

    .. math::

        R = \frac{4\pi}{(1 - g)\,\sigma_t} = \frac{4\pi}{(1 - g)\,\sigma_a + \sigma_s'}, \qquad
        A = f_g^{-1}\!\left(\frac{\sigma_s}{\sigma_t}\right).

    With g = 0, R is 4 pi transport mean free paths. (Until 2026-12-04 the export left out the
    4 pi: Cycles rendered the material with a mean free path 12.6 times too short, +4 to +123 %
    bright against F0 + T0 R_d in a white furnace; a half-shadow edge and a 1 mm slab over
    black measured a best-fit scale of 12.75.) A is Cycles' own
    parameter, not the material's diffuse reflectance: at eta = 1, g = 0 the transport
    tables' total reflectance is 0.77 A at A = 0.05 and 1.05 A at A = 0.95.

    Returns
    -------
    dict with ``base_color`` (3 floats), ``subsurface_radius`` (3 floats, scene units,
    with ``subsurface_scale = 1``), ``subsurface_scale``, ``subsurface_anisotropy`` (g),
    ``ior`` (eta), ``subsurface_weight`` (1) and ``subsurface_method`` ("RANDOM_WALK").
    """
    sigma_a, sigma_s, eta = scattering_coefficients(medium, g=g, unit_mm=unit_mm)
    sigma_t = np.asarray(_rgb(sigma_a + sigma_s))
    if not np.all(sigma_t > 0):
        raise ValueError("a channel without extinction (sigma_a = sigma_s' = 0) has no Cycles radius.")
    alpha = np.asarray(_rgb(sigma_s)) / sigma_t
    reachable = float(cycles_albedo_from_colour(1.0, g))
    if np.any(alpha > reachable):
        warnings.warn(f"single-scattering albedo {alpha.max():.7f} is above the {reachable:.7f} that Cycles' colour "
                      "fit reaches; its colour is clamped there (a slightly darker material)", stacklevel=2)
    colour = cycles_colour_from_albedo(np.minimum(alpha, reachable), g)
    radius = CYCLES_RADIUS_SCALE / ((1.0 - float(g)) * sigma_t)
    return {"base_color": colour.tolist(), "subsurface_radius": radius.tolist(), "subsurface_scale": 1.0,
            "subsurface_anisotropy": float(g), "ior": eta, "subsurface_weight": 1.0,
            "subsurface_method": "RANDOM_WALK"}


def blender_python(medium, *, g=0.0, unit_mm=1.0, name="jsss"):
    """A Python script for Blender (4.x) that creates material NAME with :func:`blender_principled`'s inputs.

    Run it in Blender's text editor or ``blender --python FILE``; it assigns the material to
    the active object when there is one.
    """
    p = blender_principled(medium, g=g, unit_mm=unit_mm)
    return (f"# jsss: Cycles random-walk subsurface; radius in scene units of {float(unit_mm):g} mm; "
            f"g = {float(g):g}, eta = {p['ior']:.6g}\n"
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
            "if bpy.context.active_object is not None:\n"
            "    bpy.context.active_object.active_material = material\n")
