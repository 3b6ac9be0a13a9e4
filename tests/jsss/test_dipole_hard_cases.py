"""Hard cases of the dipole: no NaN/Inf, no negative values, finite gradients where they exist.

Each case states what is true of it; float32 inputs are run through the same cases.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium
from jsss.diffusion.dipole import medium_from_reflectance, profile, total_reflectance
from jsss.numerics import LowPrecisionWarning

CASES = {
    "no absorption": (0.0, 1.0, 1.3),
    "absorption >> scattering": (100.0, 0.01, 1.3),
    "no scattering": (1.0, 0.0, 1.3),
    "matched index": (0.05, 1.0, 1.0),
    "index 2.5": (0.05, 1.0, 2.5),
}
FIELDS = ("sigma_a", "sigma_s_prime", "eta")


def radii(medium):
    """r = 0, ordinary distances, and 1e3 mean free paths."""
    mfp = float(np.max(medium.mean_free_path))
    return np.array([0.0, 1e-3 * mfp, mfp, 10 * mfp, 1e3 * mfp])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("case", list(CASES))
def test_values_are_finite_and_nonnegative(case, dtype):
    """Profile and total are finite, >= 0, in the input dtype, and total <= 1."""
    medium = Medium(*(dtype(v) for v in CASES[case]))
    r = radii(medium).astype(dtype)
    values = profile(medium, r)
    total = total_reflectance(medium)
    assert values.dtype == dtype and total.dtype == dtype
    assert np.all(np.isfinite(values)) and np.all(np.asarray(values) >= 0)
    assert np.isfinite(float(total)) and 0 <= float(total) <= 1 + 1e-6


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("case", list(CASES))
def test_gradients_are_finite(case, dtype):
    """grad of the profile (every r) and the total w.r.t. all fields is finite.

    The one infinite true derivative, d total / d sigma_a at sigma_a = 0, is checked
    separately below.
    """
    medium = Medium(*(dtype(v) for v in CASES[case]))
    r = radii(medium).astype(dtype)
    grads = jax.grad(lambda m: jnp.sum(profile(m, r)))(medium)
    for field in FIELDS:
        assert np.isfinite(float(getattr(grads, field))), field
    grad_r = jax.grad(lambda x: jnp.sum(profile(medium, x)))(r)
    assert np.all(np.isfinite(grad_r))
    if case != "no absorption":
        grads = jax.grad(total_reflectance)(medium)
        for field in FIELDS:
            assert np.isfinite(float(getattr(grads, field))), field


def test_no_absorption_total_is_exactly_one_and_its_sigma_a_gradient_is_large_not_nan():
    """sigma_a = 0: total is exactly 1; d/d sigma_a is -inf in truth, returned large finite."""
    medium = Medium(0.0, 1.0, 1.3)
    assert float(total_reflectance(medium)) == 1.0
    grads = jax.grad(total_reflectance)(medium)
    assert np.isfinite(float(grads.sigma_a)) and float(grads.sigma_a) < -1e100
    assert float(grads.sigma_s_prime) == 0.0  # total stays 1 for any scattering
    assert np.isfinite(float(grads.eta))


def test_profile_gradient_at_zero_absorption_is_the_true_finite_one():
    """d R_d(r) / d sigma_a at sigma_a = 0 is finite; it equals the one-sided limit.

    (1 + s d) e^{-s d} = 1 - s^2 d^2 / 2 + s^3 d^3 / 3 - ... with s = sigma_tr, so the
    profile is R0 + a sigma_a + b sigma_a^{3/2} + ...: the slope a exists although
    sigma_tr has an infinite slope. The forward difference D(h) = a + b sqrt(h) is
    extrapolated to h = 0 as 2 D(h) - D(4h).
    """
    def forward(r, h):
        return (float(profile(Medium(h, 1.0, 1.3), r)) - float(profile(Medium(0.0, 1.0, 1.3), r))) / h

    for r in [0.0, 0.5, 3.0]:
        analytic = float(jax.grad(lambda a: profile(Medium(a, 1.0, 1.3), r))(0.0))
        h = 1e-8
        limit = 2 * forward(r, h) - forward(r, 4 * h)
        assert analytic == pytest.approx(limit, rel=1e-5)


def test_no_scattering_reflects_nothing_and_its_gradient_is_the_albedo_slope():
    """sigma_s' = 0: profile and total are 0; d total / d sigma_s' equals a forward difference."""
    medium = Medium(1.0, 0.0, 1.3)
    assert float(total_reflectance(medium)) == 0.0
    assert np.all(np.asarray(profile(medium, radii(medium))) == 0.0)
    analytic = float(jax.grad(lambda s: total_reflectance(Medium(1.0, s, 1.3)))(0.0))
    h = 1e-8
    forward = float(total_reflectance(Medium(1.0, h, 1.3))) / h
    assert analytic == pytest.approx(forward, rel=1e-5)


def test_medium_from_reflectance_extremes_and_float32_warning():
    """Rd = 0 and Rd = 1 give alpha' = 0 and 1 with finite gradients; float32 warns."""
    medium = medium_from_reflectance(np.array([0.0, 1.0]), 1.0, 1.3)
    np.testing.assert_allclose(medium.reduced_albedo, [0.0, 1.0], atol=1e-12)
    g = jax.grad(lambda x: jnp.sum(medium_from_reflectance(x, 1.0, 1.3).sigma_s_prime))(jnp.array([0.0, 1.0]))
    assert np.all(np.isfinite(g))
    with pytest.warns(LowPrecisionWarning, match="1e-8"):
        medium_from_reflectance(np.float32(0.5), np.float32(1.0), np.float32(1.3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", LowPrecisionWarning)
        medium_from_reflectance(0.5, 1.0, 1.3)  # float64: silent
