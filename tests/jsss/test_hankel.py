"""Hankel transform pair on log grids against closed-form transforms."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium, dipole, hankel


@pytest.fixture(scope="module")
def grid():
    return hankel.hankel_grid()


def gaussian(v, r):
    return jnp.exp(-(r**2) / (2 * v)) / (2 * jnp.pi * v)


@pytest.mark.parametrize("v", [1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0])
def test_gaussians_transform_to_1e4_of_their_peak(grid, v):
    """G(v, r) <-> exp(-k^2 v / 2) both ways, to 1e-4 of the peak value."""
    spectrum = np.exp(-np.asarray(grid.k) ** 2 * v / 2)
    profile = np.asarray(gaussian(v, grid.r))
    np.testing.assert_allclose(hankel.forward(grid, profile), spectrum, atol=1e-4, rtol=0)
    np.testing.assert_allclose(hankel.inverse(grid, spectrum), profile, atol=1e-4 * profile[0], rtol=0)


def test_dipole_profile_transforms_to_its_closed_form_spectrum(grid):
    """forward(dipole.profile) equals dipole.spectrum (each pole: sign(z) e^{-|z| beta} / 2)."""
    medium = Medium(np.array([0.032, 0.17, 0.48]), np.array([0.74, 0.88, 1.01]), 1.3)
    np.testing.assert_allclose(
        hankel.forward(grid, dipole.profile(medium, grid.r)), dipole.spectrum(medium, grid.k), atol=1e-4
    )
    np.testing.assert_allclose(dipole.spectrum(medium, 0.0), dipole.total_reflectance(medium), rtol=1e-15)


def test_transform_is_jittable_and_differentiable(grid):
    """d/dv of the transformed Gaussian at k equals the closed form -k^2/2 exp(-k^2 v/2)."""
    k_index = 1200

    @jax.jit
    def transformed(v):
        return hankel.forward(grid, gaussian(v, grid.r))[k_index]

    k = float(grid.k[k_index])
    v = 0.3
    assert float(jax.grad(transformed)(v)) == pytest.approx(-(k**2) / 2 * np.exp(-(k**2) * v / 2), abs=1e-4)


@pytest.mark.parametrize("kwargs", [dict(r_min=0.0), dict(r_min=10.0, r_max=1.0), dict(n=8)])
def test_bad_grids_are_rejected(kwargs):
    """Empty or inverted ranges and too few nodes raise ValueError."""
    with pytest.raises(ValueError, match="hankel_grid"):
        hankel.hankel_grid(**kwargs)


def test_a_grid_is_built_once_per_shape_and_dtype():
    """The Bessel moments take seconds: the same arguments give the same grid object; another
    size or dtype gives its own, in that dtype."""
    from jsss.layers.hankel import hankel_grid

    assert hankel_grid(n=64) is hankel_grid(n=64)
    assert hankel_grid(n=64) is not hankel_grid(n=65)
    small = hankel_grid(n=64, dtype=np.float32)
    assert small.forward_matrix.dtype == np.float32 and hankel_grid(n=64).forward_matrix.dtype == np.float64
