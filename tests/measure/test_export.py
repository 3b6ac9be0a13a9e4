"""Exports to Mitsuba 3, pbrt-v4 and Blender Cycles: the files parse, carry the medium, and
(where Mitsuba is installed) render with the energy a non-absorbing medium must return."""

import ast
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from jsss import Medium
from measure import export
from jsss.materials import jensen2001

KETCHUP = jensen2001("ketchup")


def _medium_back(root):
    """sigma_a and sigma_s from the XML's homogeneous medium (the renderer's own parametrisation)."""
    medium = root.find("medium")
    scale = float(medium.find("float[@name='scale']").get("value"))
    sigma_t = scale * np.array(medium.find("rgb[@name='sigma_t']").get("value").split(","), float)
    albedo = np.array(medium.find("rgb[@name='albedo']").get("value").split(","), float)
    g = float(medium.find("phase/float[@name='g']").get("value"))
    return sigma_t * (1 - albedo), sigma_t * albedo, g


@pytest.mark.parametrize("g, unit_mm", [(0.0, 1.0), (0.8, 1000.0)])
def test_mitsuba_xml_holds_the_medium_in_scene_units(g, unit_mm):
    """sigma_a and the real sigma_s = sigma_s' / (1 - g), in 1/(scene unit), read back from the XML."""
    root = ET.fromstring(export.mitsuba_xml(KETCHUP, g=g, unit_mm=unit_mm).split("-->\n", 1)[1])
    sigma_a, sigma_s, g_back = _medium_back(root)
    np.testing.assert_allclose(sigma_a, np.asarray(KETCHUP.sigma_a) * unit_mm, rtol=1e-8)
    np.testing.assert_allclose(sigma_s * (1 - g), np.asarray(KETCHUP.sigma_s_prime) * unit_mm, rtol=1e-8)
    assert g_back == g
    assert float(root.find("bsdf/float[@name='int_ior']").get("value")) == pytest.approx(1.3)
    assert float(root.find("shape/float[@name='radius']").get("value")) == pytest.approx(20.0 / unit_mm)


def test_pbrt_material_parses_and_holds_the_medium():
    """A tokenizer of pbrt-v4's grammar ("type name" [ values ]) reads back every parameter."""
    text = export.pbrt_material(KETCHUP, g=0.5, unit_mm=1000.0, name="ketchup")
    body = "\n".join(line for line in text.splitlines() if not line.startswith("#"))
    assert body.startswith('MakeNamedMaterial "ketchup"')
    params = {m.group(2): (m.group(1), m.group(3).split())
              for m in re.finditer(r'"(\w+) (\w+)"\s*\[\s*([^\]]*)\]', body)}
    assert params["type"] == ("string", ['"subsurface"'])
    np.testing.assert_allclose(np.array(params["sigma_a"][1], float), np.asarray(KETCHUP.sigma_a), rtol=1e-8)
    np.testing.assert_allclose(np.array(params["sigma_s"][1], float) * 0.5, np.asarray(KETCHUP.sigma_s_prime),
                               rtol=1e-8)
    assert [params[k][0] for k in ("sigma_a", "sigma_s", "scale", "eta", "g")] == ["rgb", "rgb", "float", "float",
                                                                                   "float"]
    assert float(params["scale"][1][0]) == 1000.0 and float(params["eta"][1][0]) == pytest.approx(1.3)


@pytest.mark.parametrize("g", [0.0, 0.5, 0.9])
def test_blender_parameters_give_back_the_medium_through_cycles_own_map(g):
    """Cycles 4.x scales radius R by 0.25 / pi (kernel/closure/bssrdf.h, bssrdf_setup_radius), then
    turns colour A and d = R / 4 pi into sigma_t = 1/(d (1 - g)) and alpha = f_g(A)
    (subsurface_random_walk.h); fed our export, that map returns the medium's sigma_a and
    sigma_s = sigma_s'/(1 - g). This is our reading of Cycles' sources, not a Cycles render."""
    medium = Medium(sigma_a=[0.01, 0.2, 1.0], sigma_s_prime=[2.0, 1.0, 0.5], eta=1.4)
    p = export.blender_principled(medium, g=g)
    d = np.asarray(p["subsurface_radius"]) * p["subsurface_scale"] * 0.25 / np.pi  # bssrdf_setup_radius
    sigma_t = 1.0 / (d * (1 - g))
    alpha = export.cycles_albedo_from_colour(p["base_color"], g)
    np.testing.assert_allclose(sigma_t * (1 - alpha), medium.sigma_a, rtol=1e-6)
    np.testing.assert_allclose(sigma_t * alpha * (1 - g), medium.sigma_s_prime, rtol=1e-6)
    assert p["subsurface_anisotropy"] == g and p["ior"] == pytest.approx(1.4)
    if g == 0:  # the radius is then 4 pi transport mean free paths
        np.testing.assert_allclose(p["subsurface_radius"],
                                   4 * np.pi / (np.asarray(medium.sigma_a) + medium.sigma_s_prime))
    ast.parse(export.blender_python(medium, g=g))


def test_cycles_colour_is_not_the_diffuse_reflectance():
    """Documented, not assumed: Cycles' colour differs from the half-space's total diffuse
    reflectance (transport tables, eta 1, g 0) by -23 % at A = 0.05 to +5 % at 0.95."""
    from jsss import transport

    colour = np.array([0.05, 0.5, 0.95])
    alpha = export.cycles_albedo_from_colour(colour)
    ratio = np.asarray(transport.total_reflectance(Medium(1 - alpha, alpha, 1.0), g=0.0)) / colour
    np.testing.assert_allclose(ratio, [0.77, 0.88, 1.05], atol=0.02)


def test_albedo_beyond_cycles_fit_warns():
    """Marble's single-scattering albedo 0.999 is within Cycles' fit; 1 - 1e-8 is not."""
    export.blender_principled(jensen2001("marble"))
    with pytest.warns(UserWarning, match="above the 0.9999990 that Cycles"):
        export.blender_principled(Medium(1e-8, 1.0, 1.3))


@pytest.mark.parametrize("kwargs, match", [(dict(g=1.0), "g must lie in"), (dict(unit_mm=0.0), "unit_mm must be > 0")])
def test_bad_options_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        export.pbrt_material(KETCHUP, **kwargs)


def test_one_index_per_material():
    with pytest.raises(ValueError, match="one index of refraction"):
        export.mitsuba_dict(Medium([0.1, 0.1, 0.1], [1.0, 1.0, 1.0], [1.3, 1.4, 1.5]))


def test_mitsuba_renders_the_export_and_a_white_furnace_returns_all_light():
    """A non-absorbing medium inside its dielectric, in a constant environment of radiance 1,
    must look exactly 1 everywhere (all light that enters leaves); an absorbing one darker."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    furnace = Medium(sigma_a=0.0, sigma_s_prime=0.25, eta=1.3)  # the 20 mm sphere is 5 mean free paths across
    image = np.array(mi.render(mi.load_string(export.mitsuba_xml(furnace)), spp=16))[..., :3]
    on_sphere = image[24:40, 24:40]
    assert abs(on_sphere.mean() - 1.0) < 0.02
    dark = np.array(mi.render(mi.load_string(export.mitsuba_xml(Medium(0.1, 0.25, 1.3))), spp=16))[..., :3]
    assert dark[24:40, 24:40].mean() < 0.8 * on_sphere.mean()
