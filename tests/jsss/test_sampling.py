"""Exact dipole importance sampling: distribution, extremes, and unbiased MIS estimates."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats
from scipy.integrate import quad

from jsss import Medium, dipole
from jsss.diffusion.sampling import dipole_cdf, dipole_pdf, mis_integrate, sample_dipole_radius

MEDIA = [Medium(0.01, 1.0, 1.3), Medium(0.5, 1.0, 1.0), Medium(0.0, 2.0, 1.5), Medium(0.002, 2.6, 1.5)]


@pytest.mark.parametrize("medium", MEDIA)
def test_samples_pass_a_kolmogorov_smirnov_test(medium):
    """20000 radii against the CDF of 2 pi r R_d / rho: KS p-value above 0.001."""
    key1, key2 = jax.random.split(jax.random.PRNGKey(7))
    r = np.asarray(sample_dipole_radius(medium, jax.random.uniform(key1, (20000,)), jax.random.uniform(key2, (20000,))))
    result = stats.kstest(r, lambda x: np.asarray(dipole_cdf(medium, x)))
    assert result.pvalue > 1e-3, result


@pytest.mark.parametrize("medium", MEDIA[:2])
def test_cdf_is_the_integral_of_the_pdf(medium):
    """The closed-form CDF equals quadrature of the pdf (which is 2 pi r R_d / rho)."""
    for r in [0.01, 0.3, 2.0, 10.0]:
        numeric = quad(lambda x: float(dipole_pdf(medium, x)), 0, r, limit=200)[0]
        assert float(dipole_cdf(medium, r)) == pytest.approx(numeric, abs=1e-8)


def test_extreme_uniforms_give_finite_radii():
    """xi -> 0 gives r -> 0 (no cancellation), xi -> 1 gives a large finite radius, no NaN."""
    medium = Medium(0.01, 1.0, 1.3)
    xi = jnp.array([0.0, 1e-300, 1e-12, 0.5, 1 - 1e-12, 1.0])
    r = np.asarray(sample_dipole_radius(medium, jnp.zeros_like(xi), xi))
    assert np.all(np.isfinite(r)) and r[0] == 0.0 and 0 < r[1] < r[2] < r[3] < r[4] <= r[5]
    # Small xi: the CDF near 0 is ~ (r / z)^2 (1 + sigma z) / 2, so r ~ z sqrt(2 xi / (1 + sigma z)).
    z = float(dipole.source_depths(medium)[0])
    sz = float(medium.sigma_tr) * z
    assert r[2] == pytest.approx(z * np.sqrt(2e-12 / (1 + sz)), rel=1e-5)
    # The samples invert the CDF of the chosen pole exactly.
    u = np.sqrt(1 + (r[3] / z) ** 2)
    assert np.exp(-sz * (u - 1)) / u == pytest.approx(0.5, rel=1e-12)


def test_dipole_sampling_of_the_dipole_has_zero_variance_and_mis_is_unbiased():
    """f = R_d: every sample estimates rho exactly; f = R_d * Gaussian: MIS is within 4 SE of quadrature."""
    medium = Medium(0.05, 1.0, 1.3)
    key = jax.random.PRNGKey(3)
    r = sample_dipole_radius(medium, jax.random.uniform(key, (1000,)), jax.random.uniform(jax.random.split(key)[0], (1000,)))
    per_sample = 2 * jnp.pi * r * dipole.profile(medium, r) / dipole_pdf(medium, r)
    np.testing.assert_allclose(per_sample, dipole.total_reflectance(medium), rtol=1e-10)

    def f(x):
        return dipole.profile(medium, x) * jnp.exp(-(x**2) / 2.0)

    exact = quad(lambda x: 2 * np.pi * x * float(f(x)), 0, np.inf, limit=200)[0]
    estimate, stderr = mis_integrate(f, medium, jax.random.PRNGKey(11), 20000, r_max=10.0)
    assert abs(float(estimate) - exact) < 4 * float(stderr)
    assert float(stderr) < 0.01 * exact
