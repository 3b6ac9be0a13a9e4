"""Single scattering and the BRDF approximation: normalisation, closed forms, reciprocity."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import dblquad, quad

from jsss import Medium
from jsss.diffusion.brdf import brdf
from jsss.diffusion.dipole import total_reflectance
from jsss.transport.montecarlo import random_walk
from jsss.diffusion.single_scattering import (henyey_greenstein, single_scattering, single_scattering_albedo,
                                    single_scattering_brdf, single_scattering_brdf_from_cosines)


def direction(theta, phi):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


@pytest.mark.parametrize("g", [-0.5, 0.0, 0.3, 0.85])
def test_henyey_greenstein_is_normalised_with_mean_cosine_g(g):
    """int p dOmega = 1 and int cos p dOmega = g over the sphere (quadrature)."""
    norm = quad(lambda mu: 2 * np.pi * float(henyey_greenstein(mu, g)), -1, 1, limit=200)[0]
    mean = quad(lambda mu: 2 * np.pi * mu * float(henyey_greenstein(mu, g)), -1, 1, limit=200)[0]
    assert norm == pytest.approx(1.0, abs=1e-9)
    assert mean == pytest.approx(g, abs=1e-9)


@pytest.mark.parametrize("g", [0.0, 0.7])
@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.0), (0.4, 0.9, 2.0), (1.2, 0.3, 0.5)])
def test_integrating_eq6_along_the_ray_gives_the_brdf(angles, g):
    """int_0^inf (single-scattering integrand) ds = f_r^(1) |n . w_i'| (sec. 2.2 -> 2.4)."""
    medium = Medium(0.05, 1.2, 1.4)
    theta_i, theta_o, phi = angles
    wi, wo = direction(theta_i, 0.0), direction(theta_o, phi)
    along = quad(lambda s: float(single_scattering(medium, s, wi, wo, g=g)), 0, np.inf, limit=200)[0]
    cos_i_inside = np.sqrt(1 - np.sin(theta_i) ** 2 / 1.4**2)
    assert along == pytest.approx(float(single_scattering_brdf(medium, wi, wo, g=g)) * cos_i_inside, rel=1e-8)


def test_single_scattering_albedo_of_isotropic_matched_medium_is_closed_form():
    """eta = 1, g = 0, normal incidence: int f1 cos dOmega_o = alpha (1 - ln 2) / 2."""
    medium = Medium(0.2, 1.0, 1.0)
    wi = direction(0.0, 0.0)

    def integrand(theta, phi):
        return float(single_scattering_brdf(medium, wi, direction(theta, phi))) * np.cos(theta) * np.sin(theta)

    hemispherical = dblquad(integrand, 0, 2 * np.pi, 0, np.pi / 2)[0]
    alpha = 1.0 / 1.2
    assert hemispherical == pytest.approx(alpha * (1 - np.log(2)) / 2, rel=1e-6)


def test_brdf_at_normal_incidence_and_view_is_closed_form():
    """Normal in and out, g = 0: f = alpha (1-R0)^2 / (8 pi eta^2) + (1-R0)^2 Rd / pi."""
    medium = Medium(0.02, 1.5, 1.5)
    n = direction(0.0, 0.0)
    r0 = (0.5 / 2.5) ** 2
    alpha = 1.5 / 1.52
    expected = alpha * (1 - r0) ** 2 / (8 * np.pi * 1.5**2) + (1 - r0) ** 2 * float(total_reflectance(medium)) / np.pi
    assert float(brdf(medium, n, n)) == pytest.approx(expected, rel=1e-12)


def test_brdf_is_reciprocal_and_batches_over_directions_and_channels():
    """f(w_i, w_o) = f(w_o, w_i); directions (N, 3) with an RGB medium give (N, 3)."""
    rng = np.random.default_rng(0)
    theta = rng.uniform(0, 1.4, size=(2, 16))
    phi = rng.uniform(0, 2 * np.pi, size=(2, 16))
    wi = np.stack([direction(t, p) for t, p in zip(theta[0], phi[0])])
    wo = np.stack([direction(t, p) for t, p in zip(theta[1], phi[1])])
    medium = Medium(np.array([0.01, 0.05, 0.2]), np.array([1.0, 1.5, 2.0]), 1.3)
    forward = brdf(medium, wi, wo, g=0.6)
    assert forward.shape == (16, 3)
    np.testing.assert_allclose(forward, brdf(medium, wo, wi, g=0.6), rtol=1e-12)


def test_brdf_gradients_are_finite_and_match_finite_differences():
    """d f / d (sigma_a, sigma_s', eta, g) is finite and equals central differences."""
    wi, wo = direction(0.5, 0.0), direction(0.8, 2.5)

    def f(params):
        sa, ss, eta, g = params
        return brdf(Medium(sa, ss, eta), wi, wo, g=g)

    x0 = jnp.array([0.03, 1.1, 1.35, 0.4])
    analytic = np.asarray(jax.grad(f)(x0))
    for k in range(4):
        h = 1e-6
        e = np.zeros(4)
        e[k] = h
        numeric = (float(f(x0 + e)) - float(f(x0 - e))) / (2 * h)
        assert analytic[k] == pytest.approx(numeric, rel=1e-6)


def test_g_outside_the_open_interval_is_rejected():
    """|g| >= 1 makes sigma_s = sigma_s' / (1 - g) meaningless: ValueError naming g."""
    with pytest.raises(ValueError, match="g"):
        brdf(Medium(0.1, 1.0), direction(0, 0), direction(0, 0), g=1.0)


@pytest.mark.parametrize("albedo, eta", [(0.5, 1.3), (0.9, 1.5), (0.9, 1.0)])
def test_single_scattering_albedo_matches_a_walk_stopped_after_one_collision(albedo, eta):
    """Transport truth: a random walk whose photons may collide once, then only leave.

    ``max_steps=2`` lets a photon collide once and take one more flight; only those that
    leave on it are counted in R, which is then exactly the singly scattered light per
    entering flux. Jensen's eq. 7 without the 1/eta^2 of radiance leaving a denser medium
    gives 0.064 at (0.5, 1.3), where the walk gives 0.038.
    """
    medium = Medium(1 - albedo, albedo, eta)
    walk = random_walk(medium, n_photons=60_000, max_steps=2, seed=3)
    per_entering = float(single_scattering_albedo(medium)) / (1 - ((eta - 1) / (eta + 1)) ** 2)
    assert abs(per_entering - walk.R) < 4 * walk.R_err + 1e-4, (per_entering, walk.R, walk.R_err)


def test_single_scattering_albedo_is_the_hemispherical_integral_at_oblique_incidence():
    medium = Medium(0.1, 1.0, 1.4)
    theta_i = 0.9
    wi = direction(theta_i, 0.0)

    def integrand(theta, phi):
        return float(single_scattering_brdf(medium, wi, direction(theta, phi), g=0.4)) * np.cos(theta) * np.sin(theta)

    expected = dblquad(integrand, 0, 2 * np.pi, 0, np.pi / 2, epsabs=1e-10)[0]
    assert float(single_scattering_albedo(medium, np.cos(theta_i), g=0.4)) == pytest.approx(expected, rel=1e-4)


def test_single_scattering_albedo_gradients_are_finite_at_normal_incidence_and_zero_absorption():
    """d/dcos at cos = 1 (a square root of 1 - cos^2 there) and d/dsigma_a at 0 against differences."""
    d_cos = jax.grad(lambda c: single_scattering_albedo(Medium(0.1, 0.9, 1.4), c))(1.0)
    assert np.isfinite(float(d_cos))
    d_sa = float(jax.grad(lambda a: single_scattering_albedo(Medium(a, 0.9, 1.4)))(0.0))
    h = 1e-6
    fd = (float(single_scattering_albedo(Medium(h, 0.9, 1.4))) - float(single_scattering_albedo(Medium(0.0, 0.9, 1.4)))) / h
    assert d_sa == pytest.approx(fd, rel=1e-4)


def test_index_matched_brdf_is_finite_where_incidence_and_exit_both_graze():
    """At eta = 1 both refracted cosines vanish at grazing incidence and exit (a frame's
    background, where normals are zero): 1 / (cos_i' + cos_o') is infinite there, and a NaN
    there once spread to every pixel of a fit. The BRDF is 0 on that set, its gradient finite,
    and beside it the BRDF is its closed form albedo / (4 pi (cos_i + cos_o))."""
    medium = Medium(jnp.array([0.1]), jnp.array([0.9]), jnp.array([1.0]))
    value = single_scattering_brdf_from_cosines(medium, 0.0, 0.0, 0.0)
    assert np.all(np.asarray(value) == 0.0)
    grad = jax.grad(lambda a: single_scattering_brdf_from_cosines(Medium(a, 0.9, 1.0), 0.0, 0.0, 0.0).sum())(0.1)
    assert np.isfinite(float(grad))
    ci, co = 0.3, 0.6
    tangential = -np.sqrt(1 - ci**2) * np.sqrt(1 - co**2)  # opposite azimuths
    near = single_scattering_brdf_from_cosines(medium, ci, co, tangential)
    assert float(near[0]) == pytest.approx(0.9 / (4 * np.pi * (ci + co)), rel=1e-12)
