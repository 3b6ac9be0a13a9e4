"""Materials that vary over the surface: scene syntax, the texturing rules, the furnace, gradients.

The truths that share nothing with the renderer (an independent walk through a textured
absorbing layer, a path tracer with a heterogeneous medium) are in test_colour_map_truth.py
and benchmarks/textured_truth.py; here are the closed forms and conservation laws.
"""

import equinox as eqx
import imageio.v3 as iio
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss.diffusion import dipole
from jsss.medium import Medium
from jsss.render import Method, Pass, SceneError, parse_scene, plan_scene, render, render_params
from jsss.render.artist_maps import coefficients_from_artist_maps
from jsss.render.profile_blend import choose_basis
from jsss.render.surface_maps import MapSampler, blend_coefficients, srgb_to_linear
from jsss import transport
from measure.exr import write_exr
from tests.helpers import png16
from tests.jsss.render.scenes import flat_plane, scene_dict

SIZE = 32  # map texels per side


def _stripes(left, right, size=SIZE):
    """A map (texel order: row = v) that is ``left`` for u < 1/2 and ``right`` beyond."""
    u = (np.arange(size) + 0.5) / size
    values = np.empty((size, size, 3))
    values[:, u < 0.5] = left
    values[:, u >= 0.5] = right
    return values


def _write(tmp_path, name, texel_order):
    """Write a map as a linear EXR as an artist would (the file's top row is v = 1)."""
    write_exr(tmp_path / name, texel_order[::-1])
    return name


def _scene(tmp_path, maps, material=None, *, scene=None, **material_keys):
    data = scene or flat_plane(material or {"name": "marble"}, texture_size=64)
    data["material"] = dict(data["material"], maps=maps, **material_keys)
    return parse_scene(data, source="test.toml", base_dir=tmp_path)


def _frame(scene, method, **plan_keys):
    plan = plan_scene(scene, method=method, **plan_keys)
    return render(scene, plan, dtype=jnp.float64).radiance


# -- scene syntax ------------------------------------------------------------------------------


def test_eight_bit_maps_are_decoded_from_srgb_and_flipped_to_texel_order(tmp_path):
    image = np.zeros((4, 6, 3), np.uint8)
    image[0] = 255  # the file's top row: v = 1, the last row in texel order
    image[-1] = 128
    iio.imwrite(tmp_path / "c.png", image)
    maps = _scene(tmp_path, {"albedo": "c.png"}).material.maps
    assert maps.albedo.shape == (4, 6, 3)
    assert np.all(maps.albedo[-1] == 1.0) and np.all(maps.albedo[1:-1] == 0.0)
    np.testing.assert_allclose(maps.albedo[0], 0.21586, atol=1e-5)  # sRGB 128 / 255
    assert srgb_to_linear(0.04045) == pytest.approx(0.04045 / 12.92)


def test_a_16_bit_colour_png_map_keeps_its_16_bits(tmp_path):
    """Pillow cuts 16-bit colour samples to 8 bits; the map reader decodes them whole (sRGB 1/65535
    steps, every PNG filter type)."""
    codes = (np.random.default_rng(1).random((5, 4, 3)) * 65535).astype(np.uint16)
    png16(tmp_path / "c16.png", codes)
    maps = _scene(tmp_path, {"albedo": "c16.png"}).material.maps
    np.testing.assert_allclose(maps.albedo, srgb_to_linear(codes[::-1] / 65535.0), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("maps, keys, message", [
    ({"albedo": "missing.png"}, {}, r"missing.png: \[material.maps\] albedo: no such file"),
    ({"albedo": "bright.exr"}, {}, r"albedo: .*bright.exr: a reflectance must lie in \[0, 1\]"),
    ({"sigma_a": "grey.png"}, {}, r"sigma_a holds physical units and must be a linear EXR"),
    ({"sigma_a": "sa.exr", "sigma_s_prime": "small.exr"}, {}, r"sigma_s_prime: .* must have one size"),
    ({"sigma_a": "sa.exr", "diffuse_reflectance": "grey.png"}, {}, r"not both"),
    ({"albedo_map": "grey.png"}, {}, r"\[material.maps\] albedo_map: unknown key .*did you mean 'albedo'"),
    ({"albedo": "alpha.png"}, {}, r"alpha.png: \[material.maps\] albedo: has transparent pixels"),
    ({"albedo": "grey.png"}, {"texturing": "both"}, r"texturing: must be one of pre-post, pre, post"),
    ({"sigma_a": "sa.exr"}, {"normalize_profile": True}, r"contradict"),
    ({}, {}, r"give at least one map"),
])
def test_bad_maps_get_one_line_naming_the_file_and_key(tmp_path, maps, keys, message):
    iio.imwrite(tmp_path / "grey.png", np.full((8, 8), 100, np.uint8))
    iio.imwrite(tmp_path / "alpha.png", np.full((8, 8, 4), 100, np.uint8))
    write_exr(tmp_path / "bright.exr", np.full((8, 8, 3), 3.0))
    write_exr(tmp_path / "sa.exr", np.full((8, 8, 3), 0.01))
    write_exr(tmp_path / "small.exr", np.full((4, 4, 3), 1.0))
    with pytest.raises(SceneError, match=message) as error:
        _scene(tmp_path, maps, **keys)
    assert "\n" not in str(error.value)


def test_parameter_maps_need_a_homogeneous_medium(tmp_path):
    write_exr(tmp_path / "sa.exr", np.full((8, 8, 3), 0.01))
    with pytest.raises(SceneError, match=r"parameter maps vary a homogeneous medium; this material is layers"):
        _scene(tmp_path, {"sigma_a": "sa.exr"}, material={"preset": "skin"})


@pytest.mark.parametrize("model", ["dipole", "transport"])
def test_artist_maps_return_the_painted_reflectance_under_the_profile_model(model):
    medium = Medium(np.array([0.01, 0.02, 0.05]), np.array([1.0, 1.5, 2.0]), 1.3)
    rng = np.random.default_rng(0)
    reflectance = rng.uniform(0.05, 0.9, (4, 5, 3))
    mfp = rng.uniform(0.2, 3.0, (4, 5, 3))
    sigma_a, sigma_s = coefficients_from_artist_maps(medium, reflectance, mfp, (4, 5, 3), profile_model=model)
    np.testing.assert_allclose(sigma_a + sigma_s, 1 / mfp, rtol=1e-12)
    back = Medium(sigma_a, sigma_s, 1.3)
    total = dipole.total_reflectance(back) if model == "dipole" else transport.total_reflectance(back)
    np.testing.assert_allclose(np.asarray(total), reflectance, rtol=2e-3 if model == "transport" else 1e-7)


# -- the texturing rules -----------------------------------------------------------------------


@pytest.mark.parametrize("method", list(Method))
def test_a_white_map_changes_nothing_bit_for_bit(tmp_path, method):
    """The furnace for maps: c = 1 is a layer that absorbs nothing."""
    plain = parse_scene(flat_plane({"name": "marble"}, texture_size=64), source="t", base_dir=tmp_path)
    white = _scene(tmp_path, {"albedo": _write(tmp_path, "white.exr", np.ones((SIZE, SIZE, 3)))})
    np.testing.assert_array_equal(_frame(white, method), _frame(plain, method))


@pytest.mark.parametrize("method", [Method.TEXTURE_SPACE, Method.IMAGE_SPACE])
@pytest.mark.parametrize("texturing", ["pre-post", "pre", "post"])
def test_a_white_layer_through_the_map_path_returns_the_material(tmp_path, method, texturing):
    """The same furnace without the shortcut: c = 1 carried through every map operation (as a fit
    would, differentiably) returns the plain frame to rounding."""
    colour = _stripes([0.5, 0.5, 0.5], [1.0, 1.0, 1.0])
    scene = _scene(tmp_path, {"albedo": _write(tmp_path, "c.exr", colour)}, texturing=texturing)
    plain = parse_scene(flat_plane({"name": "marble"}, texture_size=64), source="t", base_dir=tmp_path)
    plan = plan_scene(scene, method=method)
    params = render_params(scene, plan, dtype=jnp.float64)
    white = eqx.tree_at(lambda p: p.maps.albedo, params, jnp.ones_like(params.maps.albedo))
    frame = plan.method_config.radiance(white, plan.method_config.prepare(scene, plan, white))
    np.testing.assert_allclose(frame, render(plain, plan, dtype=jnp.float64).radiance, rtol=1e-13, atol=1e-16)


@pytest.mark.parametrize("texturing", ["pre-post", "pre", "post"])
def test_lambert_takes_the_colour_once_whatever_the_rule(tmp_path, texturing):
    """No spread: entry and exit are one point, so every rule multiplies by c."""
    colour = _stripes([0.8, 0.5, 0.1], [0.3, 0.9, 0.6])
    scene = _scene(tmp_path, {"albedo": _write(tmp_path, "c.exr", colour)}, texturing=texturing, specular=0.0)
    plain = parse_scene(flat_plane({"name": "marble", "specular": 0.0}, texture_size=64), source="t",
                        base_dir=tmp_path)
    plan = plan_scene(scene, method=Method.LAMBERT)
    plan = plan.replace("single scattering", False, "test")
    with np.errstate(invalid="ignore"):  # 0 / 0 past the plane's rim
        ratio = render(scene, plan, dtype=jnp.float64).radiance / render(plain, plan, dtype=jnp.float64).radiance
    columns = ratio.shape[1]
    # The camera looks straight down with +y up: image columns run along x, as u does.
    rows = slice(2, -2)  # the outermost rows see past the plane's rim
    left, right = (np.float32(c).astype(float) for c in ([0.8, 0.5, 0.1], [0.3, 0.9, 0.6]))  # as the EXR holds them
    np.testing.assert_allclose(ratio[rows, 4], left * np.ones((ratio.shape[0] - 4, 1)), rtol=1e-12)
    np.testing.assert_allclose(ratio[rows, columns - 5], right * np.ones((ratio.shape[0] - 4, 1)), rtol=1e-12)


def test_texture_space_rules_bleed_as_derived(tmp_path):
    """Across a colour edge: "post" is sharp (exactly c times the plain frame); "pre" is the
    plain frame's blur of c; "pre-post" lies between them; far from the edge all three are c."""
    colour = _stripes([0.9, 0.9, 0.9], [0.1, 0.1, 0.1])
    frames = {}
    for rule in ("pre-post", "pre", "post"):
        scene = _scene(tmp_path, {"albedo": _write(tmp_path, "c.exr", colour)}, texturing=rule, specular=0.0)
        plan = plan_scene(scene, method=Method.TEXTURE_SPACE).replace("single scattering", False, "test")
        frames[rule] = render(scene, plan, dtype=jnp.float64).radiance
    plain_scene = parse_scene(flat_plane({"name": "marble", "specular": 0.0}, texture_size=64), source="t",
                              base_dir=tmp_path)
    plain = render(plain_scene, plan_scene(plain_scene, method=Method.TEXTURE_SPACE).replace(
        "single scattering", False, "test"), dtype=jnp.float64).radiance
    row = plain.shape[0] // 2
    with np.errstate(invalid="ignore"):  # 0 / 0 past the plane's rim
        r = {k: v[row, :, 0] / plain[row, :, 0] for k, v in frames.items()}
    c = np.where(np.arange(plain.shape[1]) < plain.shape[1] / 2, np.float32(0.9), np.float32(0.1))  # the EXR's
    edge = slice(plain.shape[1] // 2 - 6, plain.shape[1] // 2 + 6)
    # post: the texture at the exit point alone (up to the bilinear lookup at the edge's two pixels)
    sharp = np.abs(np.arange(plain.shape[1]) - plain.shape[1] / 2 + 0.5) > 1.5
    sharp[[0, -1]] = False  # the outermost columns see past the plane's rim
    np.testing.assert_allclose(r["post"][sharp], c[sharp], rtol=1e-9)
    # pre: light entering the bright side lights the dark side's edge, and the other way round
    assert np.all(r["pre"][edge][c[edge] < 0.5] > 0.1 + 1e-3) and np.all(r["pre"][edge][c[edge] > 0.5] < 0.9 - 1e-3)
    # pre-post: sqrt(c(x)) times the blur of sqrt(c): between the two
    lo, hi = np.minimum(r["pre"], r["post"]), np.maximum(r["pre"], r["post"])
    assert np.all(r["pre-post"][edge] >= lo[edge] - 1e-9) and np.all(r["pre-post"][edge] <= hi[edge] + 1e-9)
    for rule in r:  # far from the edge (3.7 RMS radii): c, up to the profile's tail (< 0.6 % of the contrast)
        np.testing.assert_allclose(r[rule][[3, -4]], [0.9, 0.1], atol=5e-3)


def test_normalize_profile_makes_the_map_the_colour(tmp_path):
    """d'Eon 2007 sec. 5.3: the profile normalised to white, the map alone sets the diffuse colour."""
    colour = np.full((SIZE, SIZE, 3), 0.5)
    scene = _scene(tmp_path, {"albedo": _write(tmp_path, "c.exr", colour)}, normalize_profile=True, specular=0.0)
    plain = parse_scene(flat_plane({"name": "marble", "specular": 0.0}, texture_size=64), source="t",
                        base_dir=tmp_path)
    plan = plan_scene(scene, method=Method.LAMBERT)
    total = np.asarray(render_params(plain, plan, dtype=jnp.float64).weights.sum(0))
    off = plan.replace("single scattering", False, "test")
    with np.errstate(invalid="ignore"):  # 0 / 0 past the plane's rim
        ratio = render(scene, off, dtype=jnp.float64).radiance / render(plain, off, dtype=jnp.float64).radiance
    np.testing.assert_allclose(ratio[10, 10], 0.5 / total, rtol=1e-9)


# -- parameter maps ----------------------------------------------------------------------------


def test_a_two_material_checker_sits_on_the_basis_corners():
    """Two media: a 2 x 2 basis whose blend is exact at every texel."""
    sigma_a = _stripes([0.002, 0.004, 0.007], [0.05, 0.1, 0.2])
    sigma_s = _stripes([2.2, 2.6, 3.0], [1.0, 1.2, 1.5])
    material = parse_scene(scene_dict(), source="t").material
    basis = choose_basis(material, sigma_a, sigma_s, 0.01)
    assert (len(basis.scale_nodes), len(basis.shape_nodes)) == (2, 2)
    assert basis.error < 1e-9


def test_a_gradient_is_blended_within_the_target_at_texels_the_basis_did_not_see():
    """The basis is chosen on the map's own texels; check its blend at other points of the range
    against each point's own profile (exact dipole, independent of the blend)."""
    t = np.linspace(0, 1, 64)[None, :, None] * np.ones((8, 1, 3))
    sigma_a = 0.002 * (0.2 / 0.002) ** t
    sigma_s = np.full_like(sigma_a, 1.5)
    material = parse_scene(scene_dict(), source="t").material
    target = 0.02
    basis = choose_basis(material, sigma_a, sigma_s, target)
    assert basis.error <= target and basis.size > 1
    rng = np.random.default_rng(3)
    eta = np.asarray(material.eta)
    points = Medium(0.002 * (0.2 / 0.002) ** rng.uniform(0, 1, (6, 3)), np.full((6, 3), 1.5), eta)
    coefficients = blend_coefficients(basis.scale_nodes, basis.shape_nodes, points.sigma_a, points.sigma_s_prime,
                                      xp=np)
    weights = np.einsum("pkc,knc->pnc", coefficients, basis.weights)
    r = np.geomspace(np.sqrt(basis.variances.min()) / 30, np.sqrt(basis.variances.max()) * 8, 2000)
    gaussians = np.exp(-r[:, None] ** 2 / (2 * basis.variances)) / (2 * np.pi * basis.variances)
    for p in range(6):
        exact = np.asarray(dipole.profile(Medium(points.sigma_a[p], points.sigma_s_prime[p], eta), r))
        blended = gaussians @ weights[p]
        error = np.sqrt(np.trapezoid(r[:, None] * (exact - blended) ** 2, r, axis=0)
                        / np.trapezoid(r[:, None] * exact**2, r, axis=0))
        assert np.all(error <= target + 2 * basis.fit_error), error


def _comparable(scene, plain, method):
    """A mapped frame and a plain one (64 x 64 pixels), pixel by pixel -- or for image space in
    8 x 8 blocks: the two draw their samples from two densities (the map's Gaussian mixture, the
    plain medium's dipole), so their noise differs (~11 % per pixel at 256 samples under a
    grazing lamp, ~1.5 % per block)."""
    if method is not Method.IMAGE_SPACE:
        return _frame(scene, method), _frame(plain, method)
    frames = _frame(scene, method, samples=256), _frame(plain, method, samples=256)
    return tuple(a.reshape(8, 8, 8, 8, 3).mean((1, 3)) for a in frames)


@pytest.mark.parametrize("method", [Method.TEXTURE_SPACE, Method.IMAGE_SPACE, Method.LAMBERT])
def test_a_uniform_parameter_map_renders_the_homogeneous_material(tmp_path, method):
    """A map that holds the material's own coefficients everywhere is the material: one basis node."""
    material = {"sigma_a": [0.01, 0.03, 0.08], "sigma_s_prime": [1.5, 1.8, 2.2], "eta": 1.3}
    sigma_a = np.broadcast_to(np.array(material["sigma_a"]), (SIZE, SIZE, 3))
    scene = _scene(tmp_path, {"sigma_a": _write(tmp_path, "sa.exr", sigma_a)}, material=material)
    plain = parse_scene(flat_plane(material, texture_size=64), source="t", base_dir=tmp_path)
    plan = plan_scene(scene, method=method)
    assert plan.basis.size == 1
    frame, reference = _comparable(scene, plain, method)
    lit = reference.max(-1) > 0.05 * reference.max()
    # The two plans fit their Gaussians to two targets: each within its profile error of the truth.
    tolerance = 2 * (plan.profile_error + plan_scene(plain, method=method).profile_error) + 1e-6
    np.testing.assert_allclose(frame[lit], reference[lit], rtol=tolerance)


@pytest.mark.parametrize("method", list(Method))
def test_a_uniform_map_of_another_medium_is_lit_by_that_mediums_laws(tmp_path, method):
    """A map that holds a medium other than the material's everywhere renders as that medium,
    under a slanting point lamp near the plane: the oblique-incidence law and the deposit depth
    are the map's medium's, not the material's (they had been the material's, which put a
    marble-to-skin gradient sphere 4-6 % below Mitsuba)."""
    base = {"sigma_a": [0.002, 0.004, 0.007], "sigma_s_prime": [2.2, 2.6, 3.0], "eta": 1.3}
    mapped = {"sigma_a": [0.03, 0.17, 0.48], "sigma_s_prime": [0.74, 0.88, 1.01], "eta": 1.3}
    lamp = [{"type": "point", "position": [-25.0, 0.0, 12.0], "intensity": 4000.0}]
    maps = {key: _write(tmp_path, f"{key}.exr", np.broadcast_to(np.array(mapped[key]), (SIZE, SIZE, 3)))
            for key in ("sigma_a", "sigma_s_prime")}
    data = flat_plane(base, texture_size=64)
    data["lights"] = lamp
    scene = _scene(tmp_path, maps, scene=data)
    plain = flat_plane(mapped, texture_size=64)
    plain["lights"] = lamp
    plain = parse_scene(plain, source="t", base_dir=tmp_path)
    plan = plan_scene(scene, method=method)
    assert plan.on(Pass.OBLIQUE_INCIDENCE) and plan.on(Pass.DEPOSIT_DEPTH)
    frame, reference = _comparable(scene, plain, method)
    # With the material's laws in place of the map's, every method was 14-15 % off here.
    lit = reference.max(-1) > 0.05 * reference.max()
    tolerance = 2 * (plan.profile_error + plan_scene(plain, method=method).profile_error) + 1e-6
    np.testing.assert_allclose(frame[lit], reference[lit], rtol=tolerance)


def test_light_falls_monotonically_across_a_magnified_edge(tmp_path):
    """Under uniform light the exitance falls from the clear medium to the absorbing one: the
    clear side loses light into its neighbour near the edge and the absorbing side gains it
    (the two-media walk's profile). A map coarser than the texture, read bilinearly, had put
    texels whose blend straddles the edge: read as a medium halfway between, such a texel stood
    out as a bright line (a 19 % rise here); with only the exit side read whole, the clear side
    dipped below the absorbing one (a 13 % rise after the dip). Parameter maps are now read
    whole, one medium per map texel."""
    sigma_a = _stripes([0.002, 0.004, 0.007], [0.2, 0.3, 0.5])  # a 32 x 32 map on a finer texture
    data = flat_plane({"name": "marble"}, texture_size=256)
    scene = _scene(tmp_path, {"sigma_a": _write(tmp_path, "sa.exr", sigma_a)}, scene=data)
    plan = plan_scene(scene, method=Method.TEXTURE_SPACE)
    assert plan.method_config.size >= 4 * SIZE and plan.basis.size > 1  # the map magnified, two media
    params = render_params(scene, plan, dtype=jnp.float64)
    prepared = plan.method_config.prepare(scene, plan, params)
    exitance = np.asarray(plan.method_config.exitance(params, prepared))
    x, y = prepared.texels.position[..., 0], prepared.texels.position[..., 1]
    row = np.argmin(np.abs(y[:, 0]))
    near = prepared.texels.mask[row] & (np.abs(x[row]) < 4.0)
    profile = exitance[row][near][np.argsort(x[row][near])]  # from the clear side to the absorbing one
    steps = np.diff(profile, axis=0) / profile[:-1]
    assert np.all(steps < 1e-3), f"the exitance rises by {100 * steps.max():.1f} % somewhere across the edge"


def test_image_space_and_texture_space_agree_across_a_parameter_edge(tmp_path):
    """Two methods that share only the blend: Mertens' samples with each entry point's profile
    against texture space's blur of a_k E, on a checker of two media (light crosses the edge)."""
    sigma_a = _stripes([0.002, 0.004, 0.007], [0.2, 0.3, 0.5])
    scene = _scene(tmp_path, {"sigma_a": _write(tmp_path, "sa.exr", sigma_a)})
    texture = _frame(scene, Method.TEXTURE_SPACE)
    image = _frame(scene, Method.IMAGE_SPACE, samples=256)
    sums = image.reshape(-1, 3).sum(0) / texture.reshape(-1, 3).sum(0)
    np.testing.assert_allclose(sums, 1.0, atol=0.03)


# -- gradients ---------------------------------------------------------------------------------


@pytest.mark.parametrize("method", [Method.TEXTURE_SPACE, Method.IMAGE_SPACE, Method.NORMAL_FILTERING])
@pytest.mark.parametrize("key", ["albedo", "sigma_a"])
def test_gradient_with_respect_to_every_texel_matches_finite_differences(tmp_path, method, key):
    values = _stripes([0.9, 0.6, 0.3], [0.4, 0.7, 0.2]) if key == "albedo" else \
        _stripes([0.002, 0.004, 0.007], [0.05, 0.1, 0.2])
    scene = _scene(tmp_path, {key: _write(tmp_path, "m.exr", values)})
    plan = plan_scene(scene, method=method)
    params = render_params(scene, plan, dtype=jnp.float64)
    prepared = plan.method_config.prepare(scene, plan, params)
    where = (lambda p: p.maps.albedo) if key == "albedo" else (lambda p: p.maps.sigma_a)

    def frame(texels):
        return plan.method_config.radiance(eqx.tree_at(where, params, texels), prepared).sum()

    texels = where(params)
    gradient = jax.grad(frame)(texels)
    assert np.all(np.isfinite(gradient)) and gradient.shape == texels.shape
    seen = np.argwhere(np.abs(np.asarray(gradient)).max(-1) > 0)
    assert len(seen) > 0.5 * SIZE * SIZE  # the camera sees most of the plane
    rng = np.random.default_rng(1)
    for i, j in seen[rng.choice(len(seen), 3, replace=False)]:
        for c in range(3):
            h = 1e-4 * float(texels[i, j, c])
            step = jnp.zeros_like(texels).at[i, j, c].set(h)
            difference = (frame(texels + step) - frame(texels - step)) / (2 * h)
            np.testing.assert_allclose(float(gradient[i, j, c]), float(difference), rtol=1e-4, atol=1e-9)


def test_gradient_is_finite_at_a_black_texel(tmp_path):
    """sqrt(c) at c = 0 (pre-post) must not give an infinite or NaN gradient."""
    colour = _stripes([0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    scene = _scene(tmp_path, {"albedo": _write(tmp_path, "c.exr", colour)})
    plan = plan_scene(scene, method=Method.TEXTURE_SPACE)
    params = render_params(scene, plan, dtype=jnp.float64)
    prepared = plan.method_config.prepare(scene, plan, params)
    gradient = jax.grad(lambda c: plan.method_config.radiance(eqx.tree_at(lambda p: p.maps.albedo, params, c),
                                                              prepared).sum())(params.maps.albedo)
    assert np.all(np.isfinite(gradient))


def test_map_sampler_reads_texels_bilinearly_with_u_wrapping():
    values = jnp.arange(4 * 8 * 3, dtype=jnp.float64).reshape(4, 8, 3)
    centre = MapSampler.at(np.array([[(2 + 0.5) / 8, (1 + 0.5) / 4]]), (4, 8))
    np.testing.assert_allclose(centre(values)[0], values[1, 2])
    seam = MapSampler.at(np.array([[0.0, (1 + 0.5) / 4]]), (4, 8), wrap_u=True)
    np.testing.assert_allclose(seam(values)[0], (values[1, 0] + values[1, 7]) / 2)
    box = MapSampler.texels(2, (4, 8))  # 2 x 2 texels read a 4 x 8 map: averaged over 2 x 2 blocks first
    assert box.box == 2
    np.testing.assert_allclose(np.asarray(box(values)).shape, (2, 2, 3))
    assert MapSampler.texels(4, (4, 4)).identity


def test_a_colour_map_keeps_the_texture_space_frame_linear_in_the_weights(tmp_path):
    """fit_render solves through linear_frame: with a colour map it must still be render()'s frame
    at the plan's material (the layer multiplies the irradiance and the exitance, both fixed)."""
    from jsss.render import linear_frame
    from tests.jsss.render.test_linear_frame import FIN, _weights_and_albedo

    colour = _stripes([0.9, 0.6, 0.3], [0.4, 0.7, 0.2])
    scene = _scene(tmp_path, {"albedo": _write(tmp_path, "c.exr", colour)}, scene=dict(FIN))
    plan = plan_scene(scene, method=Method.TEXTURE_SPACE)
    truth = render(scene, plan, dtype=jnp.float64).radiance
    model = np.asarray(linear_frame(scene, plan, dtype=jnp.float64).radiance(*_weights_and_albedo(scene, plan)))
    plain = render(parse_scene(FIN), plan, dtype=jnp.float64).radiance
    assert np.abs(truth - plain).max() > 0.05 * np.abs(plain).max()  # the map matters
    assert np.abs(model - truth).max() <= 1e-12 * np.abs(truth).max()
    sigma_a = _stripes([0.002, 0.004, 0.007], [0.05, 0.1, 0.2])
    mapped = _scene(tmp_path, {"sigma_a": _write(tmp_path, "sa.exr", sigma_a)}, scene=dict(FIN))
    with pytest.raises(ValueError, match="parameter maps"):
        linear_frame(mapped, plan_scene(mapped, method=Method.TEXTURE_SPACE))


def test_a_map_whose_header_declares_a_huge_image_is_refused_before_reading(tmp_path):
    """The file's own header is read first (a 600-byte EXR may declare 100000^2 pixels)."""
    import struct

    write_exr(tmp_path / "real.exr", np.ones((4, 4, 3)))
    data = (tmp_path / "real.exr").read_bytes()
    at = data.index(b"box2i", data.index(b"dataWindow")) + len(b"box2i\0") + 4
    (tmp_path / "huge.exr").write_bytes(data[:at] + struct.pack("<4i", 0, 0, 99_999, 99_999) + data[at + 16:])
    (tmp_path / "cut.exr").write_bytes(data[:100])
    for name, message in (("huge.exr", "declares 100000 x 100000 pixels"), ("cut.exr", "truncated or not an OpenEXR")):
        with pytest.raises(SceneError) as error:
            _scene(tmp_path, {"albedo": name})
        line = str(error.value)
        assert "\n" not in line and name in line and "[material.maps] albedo" in line and message in line
