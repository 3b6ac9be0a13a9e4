"""Image-space integration (Mertens 2003) against closed forms and quadrature."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, special

from jsss import dipole
from jsss.medium import Medium
from jsss.render.image_space import SampledProfile, camera_buffers, image_space_exitance, profile_radius
from jsss.render.mesh import Mesh, plane, uv_sphere
from jsss.render.raster import PerspectiveView

MEDIUM = Medium(jnp.full(3, 0.05), jnp.full(3, 1.0), 1.3)  # sigma_tr = 0.4 / mm
PROFILE = SampledProfile(medium=MEDIUM)
TOP_VIEW = PerspectiveView((0.0, 0.0, 300.0), (0.0, 0.0, 0.0), 2 * np.degrees(np.arctan(30 / 300)), 96, 96,
                           up=(0.0, 1.0, 0.0))  # 60 mm across, 0.625 mm pixels on z = 0
CENTRE = slice(36, 60)


def _exitance(buffers, E, samples, seed=0, profile=PROFILE, disc_radius=10.0):
    run = jax.jit(lambda e: image_space_exitance(profile, e, buffers, samples=samples, seed=seed,
                                                 disc_radius=disc_radius))
    return np.asarray(run(jnp.asarray(E)))


def _line_profile(u, medium):
    """Integral of the dipole along a line at distance u: each pole gives 2 sigma K1(sigma a) / a."""
    sigma, albedo = float(medium.sigma_tr[0]), float(medium.reduced_albedo[0])
    total = 0.0
    for z in dipole.source_depths(medium):
        a = np.hypot(u, float(z[0]))
        total = total + float(z[0]) * 2 * sigma * special.k1(sigma * a) / a
    return albedo / (4 * np.pi) * total


def test_line_profile_matches_direct_quadrature():
    direct = 2 * integrate.quad(lambda t: float(dipole.profile(MEDIUM, np.hypot(1.3, t))[0]), 0, 80, limit=200)[0]
    assert _line_profile(1.3, MEDIUM) == pytest.approx(direct, rel=1e-9)


def test_stripe_light_converges_to_the_analytic_response_like_one_over_sqrt_n():
    buffers = camera_buffers(plane(200.0), TOP_VIEW)
    width = 4 * 60 / 96  # four pixels: the stripe's edges lie on pixel boundaries
    x = buffers.position[..., 0]
    E = np.where(np.abs(x) < width / 2, 1.0, 0.0)[..., None] * np.ones(3)
    cols = np.arange(38, 58)
    xs = x[48, cols]
    exact = np.array([integrate.quad(_line_profile, u - width / 2, u + width / 2, args=(MEDIUM,), points=[u],
                                     limit=200)[0] for u in xs])
    counts = np.array([4, 16, 64, 256])
    errors = []
    for n in counts:
        runs = [_exitance(buffers, E, n, seed)[38:58][:, cols, 0] for seed in (0, 1)]
        errors.append(np.mean([np.sqrt(np.mean((m - exact) ** 2)) / exact.max() for m in runs]))
    slope = np.polyfit(np.log(counts), np.log(errors), 1)[0]
    assert slope < -0.4, (errors, slope)
    assert errors[-1] < 0.03


def test_pixel_errors_carry_no_period():
    """Each pixel's error is its own: no pixel repeats another's pattern (issue 20: a 4 x 4 tile
    of offsets showed as a grid with a 4-pixel period). On a uniformly lit plane seen from
    above, the error of a pixel and of its neighbours 1-8 pixels away must be uncorrelated."""
    buffers = camera_buffers(plane(200.0), TOP_VIEW)
    M = _exitance(buffers, np.ones((96, 96, 3)), 8)[16:80, 16:80, 0]
    error = M - M.mean()
    assert error.std() > 1e-4 * M.mean()  # an estimate at 8 samples is not exact
    n = error.size
    bound = 4 / np.sqrt(n)  # a correlation estimated from n independent pairs has spread 1/sqrt(n)
    for lag in range(1, 9):
        for a, b in ((error[:, lag:], error[:, :-lag]), (error[lag:], error[:-lag])):
            correlation = np.corrcoef(a.ravel(), b.ravel())[0, 1]
            assert abs(correlation) < bound, (lag, correlation)


def _tilted_plane(degrees):
    a = np.radians(degrees)
    rotation = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    m = plane(300.0, segments=4)
    return Mesh(m.vertices @ rotation.T, m.normals @ rotation.T, m.uvs, m.faces), rotation @ [0.0, 1.0, 0.0]


@pytest.mark.parametrize("degrees", [0, 60])
def test_tilted_plane_gives_the_same_response_as_an_untilted_one(degrees):
    """Irradiance 1 + 0.8 cos(k y) along the plane leaves rho + 0.8 R^(k) cos(k y) (closed form),
    however the plane is tilted against the camera (foreshortened 2x at 60 degrees)."""
    mesh, along = _tilted_plane(degrees)
    buffers = camera_buffers(mesh, TOP_VIEW)
    k = 2 * np.pi / 12
    y = buffers.position @ along
    E = (1 + 0.8 * np.cos(k * y))[..., None] * np.ones(3)
    M = _exitance(buffers, E, 128)[CENTRE, CENTRE, 0].ravel()
    yc = y[CENTRE, CENTRE].ravel()
    basis = np.stack([np.ones_like(yc), np.cos(k * yc), np.sin(k * yc)], 1)
    constant, amplitude, sine = np.linalg.lstsq(basis, M, rcond=None)[0]
    rho, hat = float(dipole.total_reflectance(MEDIUM)[0]), float(dipole.spectrum(MEDIUM, k)[0])
    assert constant == pytest.approx(rho, rel=0.02)
    assert amplitude == pytest.approx(0.8 * hat, rel=0.03)
    assert abs(sine) < 0.01 * rho


def _sphere_cap_integral(medium, radius, theta_max, cos_power):
    """Integral of R(chord) cos^p(theta) over the cap theta < theta_max of a sphere (quadrature)."""
    def f(theta):
        chord = 2 * radius * np.sin(theta / 2)
        return float(dipole.profile(medium, chord)[0]) * 2 * np.pi * radius**2 * np.sin(theta) * np.cos(theta) ** cos_power
    return integrate.quad(f, 0, theta_max, limit=200)[0]


def test_jacobian_follows_the_solid_angle_equation_on_a_sphere():
    """Uniform light on a sphere seen head-on: the estimate must equal the integral of the
    profile over the visible cap. Mertens' eq. 8 as printed (cos a / cos a' d'^2/d^2) weights
    it by cos^2, and dropping the Jacobian by cos: both are 4-7 % off, 100x the noise."""
    radius, distance = 10.0, 1000.0
    camera = PerspectiveView((0.0, -distance, 0.0), (0.0, 0.0, 0.0), 2 * np.degrees(np.arctan(11 / distance)), 128, 128)
    buffers = camera_buffers(uv_sphere(radius, segments=128, rings=64), camera)
    E = np.ones(buffers.shape + (3,)) * buffers.mask[..., None]
    estimate = _exitance(buffers, E, 1024, disc_radius=None)[60:68, 60:68, 0].mean()
    cap = np.arccos(radius / distance)
    physical, none, printed = (_sphere_cap_integral(MEDIUM, radius, cap, p) for p in (0, 1, 2))
    assert estimate == pytest.approx(physical, rel=0.003)
    assert abs(none / physical - 1) > 0.03 and abs(printed / physical - 1) > 0.06


def _small_sphere_scene():
    camera = PerspectiveView((0.0, -80.0, 20.0), (0.0, 0.0, 0.0), 20, 32, 32)
    buffers = camera_buffers(uv_sphere(10.0, segments=48, rings=24), camera)
    light = np.array([0.5, -0.5, 0.7]) / np.linalg.norm([0.5, -0.5, 0.7])
    E = np.clip(buffers.normal @ light, 0, None)[..., None] * np.array([1.0, 0.8, 0.6]) * buffers.mask[..., None]
    return buffers, E


@pytest.mark.parametrize("sigma_a", [0.02, 0.0])
def test_gradient_in_the_material_matches_finite_differences_and_is_finite_at_zero_absorption(sigma_a):
    buffers, E = _small_sphere_scene()
    E = jnp.asarray(E)

    def total(a):
        profile = SampledProfile(medium=Medium(a * jnp.ones(3), jnp.array([1.0, 1.2, 1.5]), 1.3),
                                 channel_weights=jnp.array([0.5, 0.3, 0.2]))  # fixed: no channel switches
        return image_space_exitance(profile, E, buffers, samples=16, disc_radius=8.0).sum()

    grad = jax.grad(total)(sigma_a)
    assert np.isfinite(grad)
    if sigma_a > 0:
        h = 1e-6
        fd = (total(sigma_a + h) - total(sigma_a - h)) / (2 * h)
        assert float(grad) == pytest.approx(float(fd), rel=1e-4)


def test_gaussian_sum_profile_sampler_matches_its_density():
    variances = jnp.array([0.5, 4.0, 30.0])
    weights = jnp.array([[0.3, 0.2, 0.1], [0.2, 0.2, 0.2], [0.1, 0.2, 0.3]])
    profile = SampledProfile(weights=weights, variances=variances)
    u = jax.random.uniform(jax.random.PRNGKey(0), (2, 200_000))
    r = np.asarray(profile.sample(u[0], u[1]))
    edges = np.linspace(0, 20, 41)
    counts = np.histogram(r, edges)[0] / len(r)
    mid = 0.5 * (edges[1:] + edges[:-1])
    expected = np.array([integrate.quad(lambda s: 2 * np.pi * s * float(profile.density(jnp.asarray(s))), a, b)[0]
                         for a, b in zip(edges[:-1], edges[1:])])
    assert np.allclose(counts, expected, atol=4 * np.sqrt(expected / len(r)) + 1e-4), mid
    # 95 % radius of the widest (blue) channel: sum_k w_k exp(-r^2 / 2 v_k) = 0.05 sum_k w_k.
    blue = np.asarray(weights)[:, 2]
    outside = lambda r: (blue * np.exp(-r**2 / (2 * np.asarray(variances)))).sum() - 0.05 * blue.sum()
    from scipy.optimize import brentq
    assert profile_radius(profile) == pytest.approx(brentq(outside, 0.1, 100), rel=1e-3)


def test_bad_knobs_are_named():
    buffers, E = _small_sphere_scene()
    with pytest.raises(ValueError, match="samples"):
        image_space_exitance(PROFILE, jnp.asarray(E), buffers, samples=0)
    with pytest.raises(ValueError, match="uniform_fraction"):
        image_space_exitance(PROFILE, jnp.asarray(E), buffers, uniform_fraction=1.0)
    with pytest.raises(ValueError, match="exactly one"):
        SampledProfile()
