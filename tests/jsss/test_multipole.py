"""Multipole slabs: limits, energy conservation, closed-form sums, stability and gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium, dipole, hankel
from jsss.fresnel import internal_reflection_parameter
from jsss.diffusion.multipole import (
    slab_geometry,
    slab_profiles,
    slab_spectra,
    slab_totals,
    unscattered_transmittance,
)
from tests.helpers import central_difference, radial_integral

MEDIA = [Medium(0.01, 1.0, 1.4), Medium(0.2, 3.0, 1.3), Medium(0.002, 2.6, 1.5), Medium(0.05, 0.8, 1.0)]


@pytest.mark.parametrize("medium", MEDIA)
def test_thick_slab_is_the_dipole(medium):
    """d = 1000 mean free paths: R(r) equals dipole.profile to 1e-6 and T vanishes."""
    d = 1000 * float(medium.mean_free_path)
    r = np.concatenate([[0.0], np.logspace(-3, 1.5, 60)])
    R, T = slab_profiles(medium, d, r)
    np.testing.assert_allclose(R, dipole.profile(medium, r), rtol=1e-6)
    R_total, T_total = slab_totals(medium, d)
    assert float(R_total) == pytest.approx(float(dipole.total_reflectance(medium)), rel=1e-12)
    assert float(T_total) < 1e-12


@pytest.mark.parametrize("eta_top, eta_bottom", [(1.0, 1.0), (1.4, 1.4), (1.5, 1.0), (1.0, 1.33)])
@pytest.mark.parametrize("d_over_mfp", [1e-4, 0.01, 0.3, 1.0, 3.0, 30.0])
def test_energy_is_conserved_without_absorption(d_over_mfp, eta_top, eta_bottom):
    """sigma_a = 0: R + T + unscattered = 1 exactly, for thin and thick slabs alike."""
    medium = Medium(0.0, 1.0, 1.4)
    R, T = slab_totals(medium, d_over_mfp, eta_top=eta_top, eta_bottom=eta_bottom)
    assert float(R) >= 0 and float(T) >= 0
    assert float(R + T + unscattered_transmittance(medium, d_over_mfp)) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("medium", MEDIA)
@pytest.mark.parametrize("d", [0.01, 0.5, 2.0, 10.0])
def test_absorbing_slabs_lose_energy(medium, d):
    """With absorption R + T + unscattered < 1, each of R, T >= 0."""
    R, T = slab_totals(medium, d)
    assert 0 <= float(R) and 0 <= float(T)
    assert float(R + T + unscattered_transmittance(medium, d)) < 1


@pytest.mark.parametrize("source", ["first-collision", "mean-free-path"])
@pytest.mark.parametrize("d", [0.3, 2.0])
def test_closed_form_totals_equal_quadrature_of_the_pole_sum(d, source):
    """slab_totals (infinite image train, geometric series) = 2 pi int r R(r) dr of the profiles."""
    medium = Medium(0.3, 1.5, 1.4)  # absorbing, so a truncated train converges in total too
    R_total, T_total = slab_totals(medium, d, source=source)
    numeric = radial_integral(lambda r: jnp.stack(slab_profiles(medium, d, r, n_dipoles=60, source=source), -1),
                              1e-6, 1e3, n=20001)
    np.testing.assert_allclose(numeric, [float(R_total), float(T_total)], rtol=1e-6)


def test_spectra_equal_the_hankel_transform_of_the_profiles():
    """slab_spectra(k) = forward Hankel transform of slab_profiles, to 1e-4."""
    grid = hankel.hankel_grid(1e-4, 1e3, 1024)
    medium = Medium(0.1, 2.0, 1.3)
    R, T = slab_profiles(medium, 0.7, grid.r, n_dipoles=40)
    R_hat, T_hat = slab_spectra(medium, 0.7, grid.k)
    np.testing.assert_allclose(hankel.forward(grid, R), R_hat, atol=2e-4)
    np.testing.assert_allclose(hankel.forward(grid, T), T_hat, atol=2e-4)


def test_donner_jensen_source_gives_negative_transmittance_for_thin_slabs():
    """The reason for the first-collision source, checked: with the real source at one mean
    free path and sigma_a = 0, T = (2 l - 2 d - 2 z_b) / P < 0 whenever d < l."""
    medium = Medium(0.0, 1.0, 1.4)
    d = 0.3
    _, T = slab_totals(medium, d, source="mean-free-path")
    zb = 2 * float(internal_reflection_parameter(1.4)) / 3
    period = 2 * (d + 2 * zb)
    assert float(T) == pytest.approx((2 * 1.0 - 2 * d - 2 * zb) / period, abs=1e-12)
    assert float(T) < 0
    assert float(slab_totals(medium, d)[1]) > 0  # the default source


def test_first_collision_source_lies_inside_the_slab():
    """z0 in (0, d) with z0 -> d/2 for thin slabs and -> l for thick ones; weight = 1 - e^{-d/l}."""
    medium = Medium(0.1, 0.9, 1.3)
    d = jnp.array([1e-8, 1e-3, 0.5, 1.0, 5.0, 100.0])
    geo = slab_geometry(medium, d)
    assert np.all(np.asarray(geo.z0) > 0) and np.all(np.asarray(geo.z0) < np.asarray(d))
    np.testing.assert_allclose(geo.z0[:2], d[:2] / 2, rtol=1e-3)
    assert float(geo.z0[-1]) == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(geo.weight, -np.expm1(-np.asarray(d)), rtol=1e-12)


@pytest.mark.parametrize("d", [1e-6, 1e-3, 1.0, 1e3])
@pytest.mark.parametrize("sigma_a", [0.0, 0.01, 50.0])
def test_hard_cases_are_finite(sigma_a, d):
    """Thin, thick, non-absorbing and strongly absorbing slabs at r up to 1e4 mm: finite values
    and gradients (in sigma_a, sigma_s', eta, thickness), no NaN."""
    medium = Medium(sigma_a, 1.0, 1.4)
    r = np.array([0.0, 1e-4, 0.1, 10.0, 1e4])
    R, T = slab_profiles(medium, d, r)
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(T))
    totals = slab_totals(medium, d)
    assert all(np.isfinite(float(x)) for x in totals)

    def summary(x):
        m = Medium(x[0], x[1], x[2])
        R_total, T_total = slab_totals(m, x[3])
        R_r, T_r = slab_profiles(m, x[3], r, n_dipoles=8)
        return R_total + T_total + jnp.sum(R_r) + jnp.sum(T_r)

    grads = jax.grad(summary)(jnp.array([sigma_a, 1.0, 1.4, d]))
    assert np.all(np.isfinite(grads)), grads


@pytest.mark.parametrize("d", [0.05, 0.8, 4.0])
def test_gradients_in_every_argument_equal_finite_differences(d):
    """d(R_total, T_total, R(r), T(r)) / d(sigma_a, sigma_s', eta, thickness, eta_top, eta_bottom)."""
    x0 = np.array([0.05, 1.2, 1.4, d, 1.3, 1.1])

    def outputs(x):
        m = Medium(x[0], x[1], x[2])
        R, T = slab_totals(m, x[3], eta_top=x[4], eta_bottom=x[5])
        Rr, Tr = slab_profiles(m, x[3], 0.4, eta_top=x[4], eta_bottom=x[5], n_dipoles=20)
        return jnp.stack([R, T, Rr, Tr])

    jac = np.asarray(jax.jacobian(outputs)(jnp.asarray(x0)))
    assert np.all(np.isfinite(jac))
    for j in range(x0.size):
        for i in range(4):
            def component(v, i=i, j=j):
                x = x0.copy()
                x[j] = v
                return outputs(jnp.asarray(x))[i]
            assert jac[i, j] == pytest.approx(central_difference(component, x0[j]), rel=1e-5, abs=1e-9)


def test_profiles_pick_a_static_pair_count_inside_jit():
    """n_dipoles=None works under jit (a documented default) and matches the eager result."""
    medium = Medium(0.05, 1.0, 1.4)
    jitted = jax.jit(lambda m, d: slab_profiles(m, d, jnp.array([0.0, 0.5]))[0])
    np.testing.assert_allclose(jitted(medium, 1.0), slab_profiles(medium, 1.0, jnp.array([0.0, 0.5]))[0], rtol=1e-6)


@pytest.mark.parametrize("kwargs, name", [(dict(thickness=-1.0), "thickness"), (dict(thickness=1.0, eta_top=0.0), "eta_top"),
                                          (dict(thickness=1.0, source="middle"), "source")])
def test_bad_arguments_raise_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        slab_totals(Medium(0.1, 1.0), **kwargs)
