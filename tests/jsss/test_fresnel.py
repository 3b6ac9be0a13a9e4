"""Fresnel reflectance: closed forms at normal incidence and the diffuse fits against quadrature."""

import jax
import numpy as np
import pytest
from scipy.integrate import quad

from jsss.fresnel import diffuse_fresnel_reflectance, diffuse_fresnel_transmittance, fresnel_reflectance
from tests.helpers import external_diffuse_transmittance


@pytest.mark.parametrize("eta", [0.7, 1.0, 1.33, 1.5, 2.5])
def test_normal_incidence_reflectance_is_the_closed_form(eta):
    """At normal incidence Fr = ((eta - 1) / (eta + 1))^2."""
    assert float(fresnel_reflectance(1.0, eta)) == pytest.approx(((eta - 1) / (eta + 1)) ** 2, abs=1e-15)


def test_total_internal_reflection_beyond_the_critical_angle():
    """Leaving glass (relative index 1/1.5) at 60 degrees is totally reflected."""
    assert float(fresnel_reflectance(np.cos(np.radians(60)), 1 / 1.5)) == 1.0
    assert float(fresnel_reflectance(np.cos(np.radians(30)), 1 / 1.5)) < 1.0


@pytest.mark.parametrize("eta", [0.6, 0.8, 1.0, 1.2, 1.3, 1.5, 1.8, 2.0])
def test_diffuse_fresnel_fit_matches_the_exact_integral(eta):
    """The rational fits for Fdr are within 0.01 of 2 int Fr(cos, 1/eta) cos sin dtheta.

    Fdr is the reflectance for diffuse light inside the medium meeting the boundary to
    the outside, so the exact Fresnel term is taken with relative index 1/eta.
    """
    def integrand(theta):
        return 2 * float(fresnel_reflectance(np.cos(theta), 1 / eta)) * np.cos(theta) * np.sin(theta)

    critical = np.arcsin(min(1.0, 1 / eta))
    exact = quad(integrand, 0, critical, limit=200)[0] + quad(integrand, critical, np.pi / 2, limit=200)[0]
    assert float(diffuse_fresnel_reflectance(eta)) == pytest.approx(exact, abs=0.01)


def test_diffuse_fresnel_fits_join_continuously_at_eta_1():
    """Fdr has no jump at eta = 1, so derivatives in eta are meaningful there."""
    eps = 1e-9
    below, above = float(diffuse_fresnel_reflectance(1 - eps)), float(diffuse_fresnel_reflectance(1 + eps))
    assert abs(below - above) < 1e-8


@pytest.mark.parametrize("eta", [0.6, 0.8, 1.0, 1.3, 1.5, 2.5])
def test_diffuse_transmittance_is_the_exact_external_integral(eta):
    """T_dr = int Ft(mu, eta) 2 mu dmu from outside, by adaptive quadrature of a NumPy Fresnel."""
    tol = 1e-8 if eta >= 1 else 1e-5
    assert float(diffuse_fresnel_transmittance(eta)) == pytest.approx(external_diffuse_transmittance(eta), abs=tol)


@pytest.mark.parametrize("eta", [1.1, 1.3, 1.5, 2.0])
def test_external_transmittance_is_eta_squared_times_the_internal_one(eta):
    """Refraction conserves eta^2 cos dw, so 1 - Fdr_ext = eta^2 (1 - Fdr_int), both by quadrature.

    The internal side is integrated from the inside (relative index 1/eta, total internal
    reflection past the critical angle); jsss's Fdr fit agrees within its stated 0.01.
    """
    inside = 1 - quad(lambda mu: float(fresnel_reflectance(mu, 1 / eta)) * 2 * mu, 0, 1, points=[np.sqrt(1 - 1 / eta**2)],
                      limit=200)[0]
    assert float(diffuse_fresnel_transmittance(eta)) == pytest.approx(eta**2 * inside, abs=1e-7)
    assert float(diffuse_fresnel_transmittance(eta)) == pytest.approx(
        eta**2 * (1 - float(diffuse_fresnel_reflectance(eta))), abs=0.01 * eta**2)


def test_diffuse_transmittance_gradient_is_finite_at_eta_1_and_matches_differences():
    grad = jax.grad(lambda e: diffuse_fresnel_transmittance(e))
    assert np.isfinite(float(grad(1.0)))
    for eta in (1.3, 1.5):
        h = 1e-6
        fd = (external_diffuse_transmittance(eta + h) - external_diffuse_transmittance(eta - h)) / (2 * h)
        assert float(grad(eta)) == pytest.approx(fd, rel=1e-5)
