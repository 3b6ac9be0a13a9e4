"""Oblique incidence: Chandrasekhar's H function against its moment identity and random walks."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium
from jsss import transport
from jsss.diffusion.incidence import h_function, incidence_ratio, index_matched_brdf, plane_albedo
from jsss.transport.montecarlo import random_walk


@pytest.mark.parametrize("albedo", [0.3, 0.75, 0.99, 0.999, 0.99999, 1 - 1e-8, 1.0])
def test_h_function_meets_its_zeroth_moment_identity(albedo):
    """int_0^1 H dmu = (2 / albedo) (1 - sqrt(1 - albedo)) (Chandrasekhar 1960, eq. IV.(60))."""
    mu = np.linspace(0.0, 1.0, 4001)
    H = np.asarray(h_function(jnp.asarray(albedo), jnp.asarray(mu)))
    held = min(albedo, 1 - 1e-12)  # an albedo of 1 is held just below it (largest_albedo)
    assert np.trapezoid(H, mu) == pytest.approx(2 / held * (1 - np.sqrt(1 - held)), rel=2e-7)
    assert float(h_function(jnp.asarray(albedo), 0.0)) == pytest.approx(1.0, abs=1e-12)


def _h_by_quadrature(mu, albedo):
    """H from its closed integral (Chandrasekhar 1960, eq. V.(19)), which shares nothing with
    the nodes' equation: ln H(mu) = -(mu / pi) int_0^{pi/2} ln(1 - albedo theta cot theta) /
    (cos^2 theta + mu^2 sin^2 theta) d theta."""
    from scipy.integrate import quad

    def integrand(theta):
        return np.log(1 - albedo * theta / np.tan(theta)) / (np.cos(theta) ** 2 + mu**2 * np.sin(theta) ** 2)

    with np.errstate(all="ignore"):
        value, _ = quad(integrand, 0.0, np.pi / 2, limit=400, epsabs=1e-13, epsrel=1e-13)
    return float(np.exp(-mu / np.pi * value))


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@pytest.mark.parametrize("albedo", [0.5, 0.9, 0.99999, 1.0])
def test_h_function_is_its_closed_integral_up_to_conservative_scattering(albedo):
    """Up to albedo 1, where the 1/H iteration alone had not converged (H(1) 3.92 at albedo
    1 - 1e-6 for 2.9028, 6.43 at 1): H(0.5) and H(1) as the closed integral gives them (at albedo 1 within
    the 1e-6 that holding it at 1 - 1e-12 costs); the NumPy twin the planner uses agrees; the
    slope in the albedo is finite and, below 1, a central difference's."""
    from jsss.diffusion.incidence import h_function_numpy

    mu = np.array([0.5, 1.0])
    H = np.asarray(h_function(jnp.asarray(albedo), jnp.asarray(mu)))
    truth = [_h_by_quadrature(m, albedo) for m in mu]
    np.testing.assert_allclose(H, truth, rtol=5e-6 if albedo == 1.0 else 1e-8)
    np.testing.assert_allclose(h_function_numpy(np.asarray(albedo), mu), H, rtol=1e-12)
    slope = float(jax.grad(lambda a: h_function(a, 1.0))(jnp.asarray(albedo)))
    assert np.isfinite(slope)
    if albedo < 0.999:
        step = 1e-6
        central = (float(h_function(jnp.asarray(albedo + step), 1.0))
                   - float(h_function(jnp.asarray(albedo - step), 1.0))) / (2 * step)
        assert slope == pytest.approx(central, rel=1e-6)


@pytest.mark.parametrize("cos_incident", [1.0, 0.7, 0.4])
def test_plane_albedo_is_what_a_random_walk_returns_at_oblique_incidence(cos_incident):
    """An index-matched half space of albedo 0.75, photons arriving at the given cosine: the
    walk (independent of H) returns 1 - H(mu) sqrt(1 - albedo) within its own noise."""
    walk = random_walk(Medium(0.25, 0.75, 1.0), cos_incident=cos_incident, n_photons=50_000, seed=3,
                       progress=False)
    expected = float(plane_albedo(jnp.asarray(0.75), cos_incident))
    assert abs(walk.R - expected) < 4 * walk.R_err + 1e-4, (walk.R, walk.R_err, expected)


def test_plane_albedo_at_normal_incidence_is_the_transport_tables_total():
    """The tables come from their own walks (radially binned, absorption reweighted)."""
    medium = Medium(jnp.array([0.061, 0.0021]), jnp.array([0.18, 2.19]), jnp.array([1.0, 1.0]))
    albedo = medium.sigma_s_prime / (medium.sigma_a + medium.sigma_s_prime)
    np.testing.assert_allclose(np.asarray(plane_albedo(albedo, 1.0)), np.asarray(transport.total_reflectance(medium)),
                               rtol=5e-3)


@pytest.mark.parametrize("eta", [1.3, 1.5])
def test_behind_a_fresnel_boundary_the_ratio_is_an_upper_bound_within_three_points(eta):
    """The law at the refracted cosine ignores internal reflection, which randomises the
    returning light: measured against walks through the boundary at 66 degrees it overstates
    the growth by 1.6-2.8 points of the normal beam's reflectance (the walks' noise: 0.7)."""
    medium = Medium(0.25, 0.75, eta)
    normal = random_walk(medium, n_photons=100_000, seed=5, progress=False)
    slanted = random_walk(medium, cos_incident=0.4, n_photons=100_000, seed=6, progress=False)
    measured = slanted.R / normal.R
    noise = measured * np.hypot(slanted.R_err / slanted.R, normal.R_err / normal.R)
    law = float(incidence_ratio(Medium(jnp.array([0.25]), jnp.array([0.75]), jnp.array([eta])), 0.4)[0])
    assert measured > 1.05  # the effect is real behind the boundary too
    assert law > measured - 3 * noise
    assert law - measured < 0.03 + 3 * noise


def test_incidence_ratio_is_one_at_normal_incidence_and_its_gradient_is_finite_at_the_hard_cases():
    """Normal incidence gives 1 exactly; grazing (cos 0), no absorption (albedo 1) and eta 1
    keep jax.grad finite."""
    medium = Medium(jnp.array([0.061, 0.0, 1.45]), jnp.array([0.18, 2.0, 0.03]), jnp.array([1.0, 1.3, 1.5]))
    np.testing.assert_allclose(np.asarray(incidence_ratio(medium, 1.0)), 1.0, atol=1e-12)
    for cos in (0.0, 0.5, 1.0):
        grad = jax.grad(lambda a: incidence_ratio(Medium(a, medium.sigma_s_prime, medium.eta), cos).sum())(
            medium.sigma_a)
        assert np.isfinite(np.asarray(grad)).all(), cos


def test_index_matched_brdf_is_the_exit_angle_histogram_of_a_walk():
    """A walk of albedo 0.75 entering at cos 0.6: the light leaving per unit cosine is
    dR/dmu = 2 pi mu f_r(mu, mu0); binned in mu (8 bins), each within the walk's noise."""
    from jsss.transport.montecarlo import _params
    from jsss.transport.photon_walk import run_walk

    medium = Medium(0.25, 0.75, 1.0)
    params = _params([medium], [np.inf], g=0.0, eta_above=1.0, eta_below=1.0, relative=True)
    records = run_walk(params + (jnp.asarray(0.6),), n_photons=200_000, seed=11, progress=False)
    up = records.side == 1
    edges = np.linspace(0.0, 1.0, 9)
    counts = np.histogram(records.exit_cos[up], edges, weights=records.weight[up])[0] / records.weight.size
    squares = np.histogram(records.exit_cos[up], edges, weights=records.weight[up] ** 2)[0] / records.weight.size
    noise = np.sqrt(np.maximum(squares - counts**2, 0) / records.weight.size)
    mu = np.linspace(0.0, 1.0, 801)
    density = 2 * np.pi * mu * np.asarray(index_matched_brdf(jnp.asarray(0.75), 0.6, jnp.asarray(mu)))
    expected = np.array([np.trapezoid(density[(mu >= a) & (mu <= b)], mu[(mu >= a) & (mu <= b)])
                         for a, b in zip(edges[:-1], edges[1:])])
    assert np.all(np.abs(counts - expected) < 4 * noise + 2e-4), (counts, expected, noise)
    assert counts.sum() == pytest.approx(float(plane_albedo(jnp.asarray(0.75), 0.6)), abs=4 * noise.sum())


def test_a_channel_that_does_not_scatter_has_the_ratio_one_not_nan():
    """sigma_s' = 0 in one channel: no light returns at any angle, so the law is 1 there (it had
    been 0/0); the other channels, the NumPy path and the gradient are unchanged and finite."""
    import warnings

    medium = Medium(jnp.array([0.1, 0.2, 0.3]), jnp.array([0.0, 1.0, 2.0]), 1.3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the NumPy path had warned "invalid value encountered in divide"
        numbers = np.asarray(incidence_ratio(medium, np.array([0.2, 0.7])))
    traced = np.asarray(jax.jit(lambda m: incidence_ratio(m, jnp.array([0.2, 0.7])))(medium))
    np.testing.assert_array_equal(numbers[:, 0], 1.0)
    np.testing.assert_allclose(traced, numbers, rtol=1e-12)
    alone = np.asarray(incidence_ratio(Medium(jnp.array([0.2, 0.3]), jnp.array([1.0, 2.0]), 1.3), np.array([0.2, 0.7])))
    np.testing.assert_allclose(numbers[:, 1:], alone, rtol=1e-14)
    grad = jax.grad(lambda s: jax.jit(lambda m: incidence_ratio(m, 0.5))(
        Medium(medium.sigma_a, s, medium.eta)).sum())(medium.sigma_s_prime)
    assert np.isfinite(np.asarray(grad)).all()


def test_h_function_loads_no_scipy():
    """h_function runs in every render's start (the exit law): its Newton steps solve by
    elimination in array operations, since jnp.linalg.solve's first LAPACK call loads SciPy's
    BLAS (0.12 s; the render command's cold start went from 2.70x to 3.06x `import jax`,
    2026-12-07). A fresh interpreter, as a command's start is."""
    import subprocess
    import sys

    code = ("import sys, jax, jax.numpy as jnp; from jsss.diffusion.incidence import h_function; "
            "h_function(jnp.asarray([0.5, 1.0]), jnp.asarray(1.0)).block_until_ready(); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
