"""fitting.statistics against closed forms: a straight-line fit, a direction the data cannot see."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting.statistics import covariance, error_scale, reduced_chi2, standard_errors


def test_a_straight_line_fit_has_the_textbook_covariance():
    """y = a + b x with unit errors: cov = (X^T X)^-1 (Bevington eq. 6.21), and the error of
    a + b x0 by the delta method is sqrt([1, x0] cov [1, x0]^T)."""
    x = np.linspace(-1.0, 2.0, 7)
    J = np.stack([np.ones_like(x), x], 1)
    n, sx, sxx = len(x), x.sum(), (x**2).sum()
    delta = n * sxx - sx**2
    expected = np.array([[sxx, -sx], [-sx, n]]) / delta
    cov, null = covariance(J, 1.0)
    np.testing.assert_allclose(cov, expected, rtol=1e-12)
    assert null.shape == (2, 0)
    np.testing.assert_allclose(covariance(J, 2.5)[0], 2.5 * expected, rtol=1e-12)
    x0 = 0.7
    error = standard_errors(np.array([1.0, x0]), cov, null)
    assert error.shape == (1,)
    assert error[0] == pytest.approx(np.sqrt(expected[0, 0] + 2 * x0 * expected[0, 1] + x0**2 * expected[1, 1]))


def test_a_direction_the_data_do_not_see_makes_what_moves_along_it_unconstrained():
    """Residuals that depend on p0 + p1 only (Lambert's image: sigma_a and sigma_s' scaled
    together): p0 and p1 have infinite errors, their sum a finite one (1/sqrt(m) for m unit
    residuals), where a pseudo-inverse would have reported sqrt(1/(4m)) for each."""
    m = 9
    J = np.ones((m, 2))
    cov, null = covariance(J, 1.0)
    assert null.shape == (2, 1)
    errors = standard_errors(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), cov, null)
    assert np.isinf(errors[0]) and np.isinf(errors[1])
    assert errors[2] == pytest.approx(1 / np.sqrt(m), rel=1e-12)


def test_chi2_per_degree_of_freedom_widens_errors_and_never_narrows_them():
    assert reduced_chi2(12.0, 10, 4) == 2.0 and reduced_chi2(3.0, 3, 3) == 3.0  # at least one degree of freedom
    assert error_scale(2.0) == 2.0 and error_scale(0.4) == 1.0
    traced = jax.jit(lambda s, m: error_scale(reduced_chi2(s, m, 2)))  # JAX values too (fit_medium's vmapped solve)
    assert float(traced(jnp.asarray(24.0), jnp.asarray(8))) == 4.0
    assert float(traced(jnp.asarray(1.0), jnp.asarray(8))) == 1.0
