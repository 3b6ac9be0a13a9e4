"""The pixel methods (Lambert, normal filtering, image-space) and the brute-force reference."""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss import dipole
from jsss.fresnel import fresnel_transmittance
from jsss.materials import jensen2001
from jsss.render import parse_scene, plan_scene, render
from jsss.render.comparison import relative_rms
from jsss.render.reference import reference_radiance, surface_samples
from tests.helpers import external_diffuse_transmittance
from tests.jsss.render.scenes import flat_plane, scene_dict


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("JSSS_CACHE_DIR", str(tmp_path))


def _diffuse(scene, method, *, flat_lobe=False, **knobs):
    plan = plan_scene(scene, method=method, **knobs).replace("specular", False, "test: diffuse only")
    plan = plan.replace("single scattering", False, "test: diffusion only")
    if flat_lobe:
        plan = plan.replace("exit angle", False, "test: the diffusion exit law")
    return render(scene, plan, dtype=jnp.float64).radiance


def _plane(material, width=200.0):
    data = flat_plane(material, width=width)
    data["camera"]["resolution"] = [24, 24]
    return parse_scene(data)


def test_lambert_on_a_lit_plane_is_the_closed_form():
    """L = rho E Ft(1) / (pi T_dr) with E = Ft(1) for a unit light at normal incidence.

    T_dr = int Ft(mu) 2 mu dmu over the outside hemisphere (quadrature here, not jsss's), so
    that all of the exitance rho E leaves; 1 - Fdr (internal) would release eta^2 rho E. The
    flat diffusion lobe's law (the exit-angle pass is off here; tests/jsss/test_exit_law.py
    checks it against Chandrasekhar's reflection and the tables' exit cones).
    """
    scene = _plane({"name": "marble"})
    medium = jensen2001("marble")
    eta = jnp.asarray(medium.eta)
    ft = np.asarray(fresnel_transmittance(jnp.ones(3), eta))
    t_dr = np.array([external_diffuse_transmittance(float(e)) for e in np.broadcast_to(medium.eta, 3)])
    expected = np.asarray(dipole.total_reflectance(medium)) * ft**2 / (np.pi * t_dr)
    L = _diffuse(scene, "lambert", flat_lobe=True)
    assert np.allclose(L[6:18, 6:18], expected, rtol=1e-4)


def test_flat_normals_filter_to_themselves_so_normal_filtering_is_lambert_on_a_plane():
    scene = _plane({"name": "ketchup"})
    lambert = _diffuse(scene, "lambert")
    for kind in ("spectral", "naive"):
        assert np.allclose(_diffuse(scene, "normal filtering", normal_filter=kind), lambert, rtol=1e-6)


def test_image_space_on_a_uniformly_lit_plane_matches_lambert_within_noise():
    """Far from the edges of a uniformly lit plane all light comes back: M = rho E."""
    scene = _plane({"name": "skin1"})
    lambert = _diffuse(scene, "lambert")[8:16, 8:16]
    inner = np.ones(lambert.shape[:2], bool)
    noise = []
    for samples in (64, 256):
        image = _diffuse(scene, "image-space", samples=samples)[8:16, 8:16]
        assert np.mean(image) == pytest.approx(np.mean(lambert), rel=0.01)  # unbiased
        noise.append(relative_rms(image, lambert, inner))
    assert noise[1] < 0.7 * noise[0]  # and the noise falls with the samples (1/2 expected)


def test_reference_matches_lambert_inside_a_uniformly_lit_plane_and_its_noise_is_small():
    scene = _plane({"name": "skin1"}, width=100.0)
    ref = reference_radiance(scene, samples=200_000)
    lambert = _diffuse(scene, "lambert")
    inner = np.zeros(ref.mask.shape, bool)
    inner[8:16, 8:16] = True
    assert relative_rms(ref.radiance, lambert, inner) < 0.01
    assert ref.noise < 0.02


def test_surface_samples_are_spread_evenly_by_area():
    from jsss.render.mesh import box

    mesh = box((30.0, 20.0, 10.0), segments=2)
    position, normal, area = surface_samples(mesh, 22_000)
    assert area == pytest.approx(2 * (600 + 300 + 200))
    on_top = np.isclose(position[:, 2], 5.0)
    assert on_top.mean() == pytest.approx(600 / 2200, abs=1e-3)  # stratified: share to within a point or two
    assert np.allclose(np.linalg.norm(normal, axis=1), 1)


@pytest.mark.parametrize("method", ["lambert", "normal filtering", "image-space"])
def test_pixel_methods_render_finite_float32_frames_with_specular(method):
    scene = parse_scene(scene_dict(material={"name": "skin1"}))
    plan = plan_scene(scene, method=method, samples=8)
    result = render(scene, plan)
    assert result.radiance.dtype == np.float32 and np.all(np.isfinite(result.radiance))
    assert result.radiance.max() > 0 and plan.method in result.plan.describe()
