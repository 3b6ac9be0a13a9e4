"""Exports to Mitsuba 3, pbrt-v4 and Blender Cycles: the files parse, carry the medium, and
(where Mitsuba is installed) render with the energy a non-absorbing medium must return."""

import ast
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from jsss import Medium, transport
from jsss.materials import jensen2001
from measure import cycles_walk, export

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
def test_blender_radius_gives_back_the_extinction_and_the_colour_the_total(g):
    """Cycles 4.x scales radius R by 0.25 / pi (kernel/closure/bssrdf.h, bssrdf_setup_radius), then
    turns colour A and d = R / 4 pi into sigma_t = 1/(d (1 - g)) and alpha = f_g(A)
    (subsurface_random_walk.h): fed our export, that map returns the medium's sigma_t, and the
    model of Cycles' walk at that alpha returns the medium's total reflectance at its eta.
    This is our reading of Cycles' sources; test_export_cycles.py renders it."""
    medium = Medium(sigma_a=[0.01, 0.2, 1.0], sigma_s_prime=[2.0, 1.0, 0.5], eta=1.4)
    p = export.blender_principled(medium, g=g)
    d = np.asarray(p["subsurface_radius"]) * p["subsurface_scale"] * 0.25 / np.pi  # bssrdf_setup_radius
    sigma_t = 1.0 / (d * (1 - g))
    np.testing.assert_allclose(sigma_t, np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime) / (1 - g),
                               rtol=1e-6)
    alpha = export.cycles_albedo_from_colour(p["base_color"], g)
    rd = np.asarray(transport.total_reflectance(medium, g=g))
    np.testing.assert_allclose(p["total_reflectance"], rd, rtol=1e-6)
    np.testing.assert_allclose(cycles_walk.walk_reflectance(alpha, g), rd, rtol=1e-4)
    assert p["subsurface_anisotropy"] == g and p["ior"] == pytest.approx(1.4) and p["roughness"] == 0.0
    if g == 0:  # the radius is then 4 pi transport mean free paths
        np.testing.assert_allclose(p["subsurface_radius"],
                                   4 * np.pi / (np.asarray(medium.sigma_a) + medium.sigma_s_prime))
    script = export.blender_python(medium, g=g)
    ast.parse(script)
    assert "node.inputs['Roughness'].default_value = 0.0" in script


def test_cycles_colour_is_not_the_diffuse_reflectance():
    """Documented, not assumed: Cycles' colour differs from the half-space's total diffuse
    reflectance (transport tables, eta 1, g 0) by -23 % at A = 0.05 to +5 % at 0.95."""
    colour = np.array([0.05, 0.5, 0.95])
    alpha = export.cycles_albedo_from_colour(colour)
    ratio = np.asarray(transport.total_reflectance(Medium(1 - alpha, alpha, 1.0), g=0.0)) / colour
    np.testing.assert_allclose(ratio, [0.77, 0.88, 1.05], atol=0.02)


# ----------------------------------------------------------------------------- the walk model's truth
def _h_function(omega, mu, nodes=64):
    """Chandrasekhar's H function of isotropic scattering, albedo ``omega`` (Radiative Transfer,
    1960, eq. V.(11)): H = 1 / (1 - (omega/2) mu int_0^1 H(mu') / (mu + mu') dmu'), on
    Gauss-Legendre nodes: iterated from H = 1 (which picks the physical root), then Newton."""
    import warnings

    from scipy import optimize

    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (x + 1), 0.5 * w
    kernel = 0.5 * omega * x[:, None] * w / (x[:, None] + x)
    h = np.ones(nodes)
    for _ in range(200):
        h = 1 / (1 - kernel @ h)
    with warnings.catch_warnings():  # at omega = 1 the Jacobian is near singular; the root is fine
        warnings.simplefilter("ignore", RuntimeWarning)
        h = optimize.fsolve(lambda h: h * (1 - kernel @ h) - 1, h, xtol=1e-14)
    return 1 / (1 - 0.5 * omega * mu * np.sum(w * h / (mu + x)))


def _exits_after_n_scatterings(n_max=255, depth=100.0, nodes=300):
    r"""P_n, n = 0..n_max: the chance that a normally incident photon leaves an index-matched
    isotropic half space after exactly n scatterings (albedo 1), by orders of scattering:
    collision density c_1 = e^{-tau}, c_{n+1}(tau) = (1/2) int E_1|tau - t| c_n(t) dt,
    P_n = (1/2) int E_2(tau) c_n(tau) dtau, with c piecewise linear on a graded grid and the
    kernels integrated exactly (E_2, E_3, E_4). Independent of any walk; 3e-4 accurate."""
    from scipy.special import expn

    tau = depth * np.expm1(6 * np.linspace(0, 1, nodes)) / np.expm1(6)

    def moments(x, a, b):  # int_a^b E1|x - t| dt and int_a^b E1|x - t| (t - a) dt
        i0, i1 = np.zeros_like(x), np.zeros_like(x)
        mid = np.clip(x, a, b)
        for sign, s0, s1 in ((-1, x - mid, x - a), (1, mid - x, b - x)):
            s0, s1 = np.maximum(s0, 0), np.maximum(s1, 0)
            j0 = expn(2, s0) - expn(2, s1)
            j1 = (s0 * expn(2, s0) + expn(3, s0)) - (s1 * expn(2, s1) + expn(3, s1))
            i0 += j0
            i1 += (x - a) * j0 + sign * j1
        return i0, i1

    kernel, escape = np.zeros((nodes, nodes)), np.zeros(nodes)
    for j in range(nodes - 1):
        a, b = tau[j], tau[j + 1]
        i0, i1 = moments(tau, a, b)
        kernel[:, j] += 0.5 * (i0 - i1 / (b - a))
        kernel[:, j + 1] += 0.5 * i1 / (b - a)
        e0 = expn(3, a) - expn(3, b)
        e1 = expn(4, a) - expn(4, b) - (b - a) * expn(3, b)
        escape[j] += 0.5 * (e0 - e1 / (b - a))
        escape[j + 1] += 0.5 * e1 / (b - a)
    collisions, p = np.exp(-tau), np.zeros(n_max + 1)
    for n in range(1, n_max + 1):
        p[n] = escape @ collisions
        collisions = kernel @ collisions
    return p


@pytest.fixture(scope="module")
def orders():
    return _exits_after_n_scatterings()


def test_h_function_and_single_scattering_check_the_orders_of_scattering(orders):
    """Published: H(1) = 2.9078 for conservative isotropic scattering (Chandrasekhar 1960,
    Table XI); single scattering of a normal beam returns (1 - ln 2)/2 exactly; and the orders
    sum to Chandrasekhar's plane albedo 1 - H(1) sqrt(1 - alpha) where the cap does not bite."""
    assert _h_function(1.0, 1.0) == pytest.approx(2.90781, abs=1e-5)
    assert orders[1] == pytest.approx((1 - np.log(2)) / 2, rel=1e-4)
    for alpha in (0.2, 0.5, 0.9):
        exact = 1 - _h_function(alpha, 1.0) * np.sqrt(1 - alpha)
        assert np.sum(alpha ** np.arange(orders.size) * orders) == pytest.approx(exact, rel=1e-4)


def test_transport_tables_at_eta_one_against_chandrasekhar():
    """The uncapped index-matched walk's total for a normal beam (the tables at eta 1, g = 0)
    against Chandrasekhar's exact plane albedo 1 - H(1) sqrt(1 - alpha): within 0.3 %."""
    alpha = np.array([0.2, 0.5, 0.9, 0.99, 0.999, 0.9999])
    tables = np.asarray(transport.total_reflectance(Medium(1 - alpha, alpha, 1.0), g=0.0))
    exact = np.array([1 - _h_function(a, 1.0) * np.sqrt(1 - a) for a in alpha])
    np.testing.assert_allclose(tables, exact, rtol=0.003)


def test_walk_model_against_orders_of_scattering_capped_at_255(orders):
    """Cycles' walk (g = 0) returns sum_{n <= 255} alpha^n P_n: the model (tables at eta 1 less
    the C n^-3/2 tail beyond the cap) within 0.3 %, where the cap costs up to 10 % of the light;
    below alpha 0.2 it is Cycles' floor, alpha / 0.2 times the walk at 0.2."""
    alpha = np.array([0.2, 0.5, 0.9, 0.99, 0.999, 0.9999, 0.999999])
    capped = np.array([np.sum(a ** np.arange(orders.size) * orders) for a in alpha])
    uncapped = np.array([1 - _h_function(a, 1.0) * np.sqrt(1 - a) for a in alpha])
    assert uncapped[-1] / capped[-1] - 1 > 0.09  # what is at stake
    np.testing.assert_allclose(cycles_walk.walk_reflectance(alpha), capped, rtol=0.003)
    low = np.array([0.01, 0.05, 0.1])
    np.testing.assert_allclose(cycles_walk.walk_reflectance(low), low / 0.2 * capped[0], rtol=0.003)


@pytest.mark.parametrize("g", [0.0, 0.8])
def test_albedo_for_reflectance_inverts_the_walk(g):
    """alpha -> R_c -> alpha round-trips (floor and cap included); reflectances above the
    walk's largest are flagged."""
    alpha = np.array([0.003, 0.05, 0.19, 0.2, 0.21, 0.5, 0.9, 0.99, 0.999, 0.99999])
    total = cycles_walk.walk_reflectance(alpha, g)
    back, reachable = cycles_walk.albedo_for_reflectance(total, g)
    np.testing.assert_allclose(back, alpha, rtol=1e-4)
    np.testing.assert_allclose(cycles_walk.walk_reflectance(back, g), total, rtol=2e-5)  # interpolation
    assert reachable.all()
    assert not cycles_walk.albedo_for_reflectance(0.95, g)[1]


def test_colour_inverts_cycles_fit():
    alpha = np.array([0.01, 0.2, 0.5, 0.9, 0.999])
    np.testing.assert_allclose(export.cycles_albedo_from_colour(export.cycles_colour_from_albedo(alpha)), alpha,
                               rtol=1e-9)


def test_total_beyond_cycles_walk_warns():
    """Marble's total (0.84 at eta 1.5) is within reach of Cycles' walk; a nearly white
    medium's (0.99) is not: the 256-bounce cap keeps the walk below 0.90."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        export.blender_principled(jensen2001("marble"))
    with pytest.warns(UserWarning, match="above the 0.899. that Cycles' walk returns"):
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


def test_mitsuba_renders_the_exported_slab_with_the_medium_total():
    """skin1's export (a box 1000 mean free paths wide and deep, volpathmis) under a uniform
    white environment, seen along the normal, against F(0) + (1 - F(0)) R_d of the transport
    tables (exact by reciprocity: benchmarks/exports.py): within 4 standard errors and the
    tables' 0.5 %. A wrong eta, sigma_s for sigma_s' or a wrong scale misses by far more."""
    pytest.importorskip("mitsuba")
    from benchmarks.exports import render_mitsuba, truth

    medium = jensen2001("skin1")
    expected = truth(medium)
    result = render_mitsuba(medium, spp=64, resolution=16)
    mean, stderr = np.asarray(result["mean"]), np.asarray(result["stderr"])
    assert np.all(stderr < 0.025 * expected)  # the check below means something
    assert np.all(np.abs(mean - expected) < 0.005 * expected + 4 * stderr), (mean / expected - 1, stderr / expected)


def test_a_clear_channel_gets_no_cycles_colour():
    """A channel without scattering (a clear liquid's, sigma_s' = 0) reflects nothing diffusely:
    colour 0, and below the tables' reduced albedo 0.001 the total falls in proportion to it
    (single scattering), continuous at the last node."""
    p = export.blender_principled(Medium([0.5, 1.0, 1.0], [0.0, 0.9e-3, 1.1e-3], 1.33))
    assert p["total_reflectance"][0] == 0.0 and p["base_color"][0] < 1e-12
    assert p["total_reflectance"][1] / p["total_reflectance"][2] == pytest.approx(0.9 / 1.1, rel=0.01)


def _render_with_map(mi, folder, medium, albedo_map, spp=16):
    """The Mitsuba preview (furnace sphere) of ``medium`` with a colour map, as the command writes
    it: the transmittance EXR in the map file's layout (array row 0, v = 0, at the file's bottom)."""
    from measure.exr import write_exr

    write_exr(folder / "map_transmittance.exr", export.prepost_transmittance(albedo_map)[::-1].astype(np.float32))
    (folder / "material.xml").write_text(export.mitsuba_xml(medium, transmittance="map_transmittance.exr"))
    return np.array(mi.render(mi.load_file(str(folder / "material.xml")), spp=spp))[..., :3]


def test_a_colour_maps_mitsuba_texture_weighs_each_crossing_by_its_sqrt(tmp_path):
    """A uniform map c on a non-absorbing sphere in a white furnace: a camera ray reflects with
    probability F (radiance 1) or enters (sqrt(c)), and all the light leaves (sqrt(c) again), so
    the sphere shows F + (1 - F) c at near-normal view: c, not sqrt(c) (one crossing weighed) nor 1
    (none). c = 1.21: a map brighter than its medium is multiplied as it is."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    c = np.array([0.25, 0.64, 1.21])
    eta = 1.3
    # 128 spp: the share of samples that reflect scatters by 0.0011 in the c = 0.25 channel (4.6 of it allowed)
    image = _render_with_map(mi, tmp_path, Medium(0.0, 0.25, eta), np.broadcast_to(c, (4, 4, 3)), spp=128)
    centre = image[28:36, 28:36].mean((0, 1))  # within 11 degrees of normal: F within 2e-4 of F(0)
    f0 = ((eta - 1) / (eta + 1)) ** 2
    assert np.all(np.abs(centre - (f0 + (1 - f0) * c)) < 0.005), centre


def test_a_colour_maps_mitsuba_texture_lies_in_jsss_uv_layout(tmp_path):
    """The map dark (c = 0.04) in its first rows, v < 1/2: jsss's sphere puts v = 0 at +z, so the
    upper half of the preview's sphere is dark (light entering there is weighed by 0.2), the lower
    light. A flipped v (Mitsuba's sphere reads an image's top row at v = 0) swaps them."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    albedo_map = np.ones((8, 8, 3))
    albedo_map[:4] = 0.04
    image = _render_with_map(mi, tmp_path, Medium(0.0, 0.25, 1.3), albedo_map).mean(-1)
    upper, lower = image[16:26, 26:38].mean(), image[38:48, 26:38].mean()
    assert upper < 0.25 and lower > 0.4, (upper, lower)


def test_a_colour_maps_blender_colour_is_the_medium_colour_times_the_map():
    """c = 1 gives the homogeneous export's Base Color; each texel's colour makes Cycles' walk
    return c R_d (the walk model inverted); the script loads the colour map into Base Color."""
    medium = jensen2001("marble")
    p = export.blender_principled(medium)
    albedo_map = np.ones((2, 3, 3))
    albedo_map[1] = [0.5, 0.8, 0.9]
    colour = export.blender_colour_map(medium, albedo_map)
    assert colour.shape == albedo_map.shape
    assert np.allclose(colour[0], p["base_color"], rtol=1e-9)
    alpha = cycles_walk.albedo_from_colour(colour[1, 0])
    returned = np.array([cycles_walk.walk_reflectance(a) for a in alpha])
    assert np.allclose(returned, albedo_map[1, 0] * np.asarray(p["total_reflectance"]), rtol=2e-3)
    script = export.blender_python(medium, colour_map="fit_colour.exr")
    ast.parse(script)
    assert "'fit_colour.exr'" in script and "node.inputs['Base Color']" in script.split("links.new(")[-1]
    with pytest.warns(UserWarning, match="Cycles' walk returns"):
        export.blender_colour_map(medium, np.full((1, 1, 3), 1.5))


@pytest.mark.parametrize("bad", [np.full((2, 2, 3), -0.1), np.full((2, 2, 3), np.nan), np.ones((2, 2))])
def test_a_bad_colour_map_is_named(bad):
    with pytest.raises(ValueError, match="colour map"):
        export.prepost_transmittance(bad)


def test_jsss_render_fit_exports_the_fitted_medium(tmp_path, capsys, monkeypatch):
    """``jsss-render fit --export``: the files sit beside the .fit.toml and carry the fitted
    medium (the .fit.json's), in scene units of --unit-mm; a bad --unit-mm is one line, exit 2."""
    import json

    from measure.commands import render as render_command

    scene = tmp_path / "s.toml"
    scene.write_text('[geometry]\nshape = "sphere"\nradius = 20.0\n[material]\nname = "marble"\n'
                     '[[lights]]\ntype = "environment"\n'
                     '[camera]\nposition = [0.0, -110.0, 30.0]\nfov = 28\nresolution = [32, 24]\n')
    assert render_command.main([str(scene), "-o", str(tmp_path / "photo.png"), "-q"]) == 0
    argv = ["fit", str(scene), str(tmp_path / "photo.exr"), "-o", str(tmp_path / "out"), "--no-gain", "-q",
            "--method", "lambert", "--export", "mitsuba", "--export", "pbrt", "--unit-mm", "10"]
    assert render_command.main(argv) == 0
    assert "photo.fit_mitsuba.xml" in capsys.readouterr().out
    fitted = json.loads((tmp_path / "out" / "photo.fit.json").read_text())
    root = ET.fromstring((tmp_path / "out" / "photo.fit_mitsuba.xml").read_text().split("-->\n", 1)[1])
    sigma_a, sigma_s, g = _medium_back(root)
    assert np.allclose(sigma_a, 10 * np.asarray(fitted["sigma_a"]), rtol=1e-6)  # 1/(10 mm)
    assert np.allclose(sigma_s * (1 - g), 10 * np.asarray(fitted["sigma_s_prime"]), rtol=1e-6)
    assert (tmp_path / "out" / "photo.fit.pbrt").is_file()
    assert render_command.main(argv[:-1] + ["0"]) == 2
    err = capsys.readouterr().err
    assert "--unit-mm must be > 0" in err and len(err.strip().splitlines()) == 1
    # A fit whose exposure came out unresolved (R_d and the gain one direction) exports nothing, says
    # so, and exits 1: the same fit, its result marked so (what fit_render does without a reference)
    import dataclasses

    import fitting.render

    real = fitting.render.fit_render
    monkeypatch.setattr(fitting.render, "fit_render",
                        lambda *a, **k: dataclasses.replace(real(*a, **k), gain_unresolved=True))
    unresolved = argv[:3] + ["-o", str(tmp_path / "free")] + argv[5:]
    assert render_command.main(unresolved) == 1
    assert "no material exported: the exposure is unresolved" in capsys.readouterr().err
    assert (tmp_path / "free" / "photo.fit.json").is_file() and not (tmp_path / "free" / "photo.fit_mitsuba.xml").exists()


def test_a_colour_maps_declarations_do_not_flip_and_names_are_escaped():
    """The declarations alone (for an OBJ mesh, whose loader flips v itself) carry no to_uv; the
    preview's sphere does, and its header says to remove it. A quote or ampersand in the name
    leaves the XML well formed and the pbrt string closed."""
    medium = jensen2001("marble")
    alone = export.mitsuba_xml(medium, preview=False, transmittance='a&b".exr', name='x"&y')
    preview = export.mitsuba_xml(medium, transmittance="t.exr")
    assert "to_uv" not in alone and "to_uv" in preview and "remove the to_uv block" in preview
    root = ET.fromstring(alone.split("-->\n", 2)[2])
    assert root.find("bsdf/texture/string[@name='filename']").get("value") == 'a&b".exr'
    assert root.find("bsdf").get("id") == 'x"&y_bsdf'
    assert export.pbrt_material(medium, name='x"y').splitlines()[1] == 'MakeNamedMaterial "x_y"'
