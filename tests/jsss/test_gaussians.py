"""Gaussian sums: algebra against closed forms, reduction invariants, polynomial basis, pole fits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium, dipole, hankel
from jsss.gaussians import (
    GaussianSum,
    PolyGaussian,
    add,
    convolve,
    derive_pole_weights,
    empirical_dipole_fit,
    empirical_multipole_fit,
    evaluate,
    geometric_series,
    layers_as_gaussians,
    pole_weight_curves,
    poly_add,
    poly_multiply,
    poly_total,
    reduce_to,
    relative_rms_error,
    second_moment,
    to_gaussian_sum,
    total,
)
from jsss.layers.kubelka_munk import Layer, combine_spectra, skin_three_layer, stack
from jsss.materials import jensen2001, jensen2001_table
from jsss.diffusion.multipole import slab_totals
from tests.helpers import radial_integral

A = GaussianSum(jnp.array([[0.3, 0.1], [0.2, 0.4]]), jnp.array([0.05, 1.5]))
B = GaussianSum(jnp.array([[0.5, 0.2], [0.1, 0.3], [0.05, 0.05]]), jnp.array([0.0, 0.2, 4.0]))


def spectrum(gs, k):
    """Closed-form Hankel transform of a GaussianSum: sum_i w_i exp(-k^2 v_i / 2)."""
    return np.exp(-np.asarray(k)[:, None] ** 2 * np.asarray(gs.variances) / 2) @ np.asarray(gs.weights)


def test_evaluate_integrates_to_the_total():
    """2 pi int r sum dr (quadrature) equals the sum of the weights, per channel."""
    numeric = radial_integral(lambda r: evaluate(A, r), 1e-6, 1e3, n=20001)
    np.testing.assert_allclose(numeric, total(A), rtol=1e-8)


def test_convolution_is_a_product_in_frequency_space():
    """The transform of A * B equals the product of the transforms (and totals multiply)."""
    k = np.geomspace(1e-3, 30, 50)
    np.testing.assert_allclose(spectrum(convolve(A, B), k), spectrum(A, k) * spectrum(B, k), rtol=1e-12)
    np.testing.assert_allclose(total(convolve(A, B)), total(A) * total(B), rtol=1e-14)
    np.testing.assert_allclose(second_moment(convolve(A, B)),
                               second_moment(A) * total(B) + second_moment(B) * total(A), rtol=1e-12)
    assert add(A, B).n_terms == 5


def test_reduce_to_keeps_total_and_second_moment():
    """Splitting onto a sparser set keeps the total and the second moment exactly."""
    dense = GaussianSum(jnp.linspace(0.1, 1.0, 20)[:, None] * jnp.array([1.0, 0.5]), jnp.geomspace(0.02, 8.0, 20))
    sparse = reduce_to(dense, jnp.array([0.01, 0.1, 1.0, 10.0]))
    np.testing.assert_allclose(total(sparse), total(dense), rtol=1e-14)
    np.testing.assert_allclose(second_moment(sparse), second_moment(dense), rtol=1e-13)
    with pytest.raises(ValueError, match="increasing"):
        reduce_to(dense, jnp.array([1.0, 0.5]))


def random_poly(seed, degree, scale, support=10):
    """Random non-negative coefficients on the first ``support`` powers, summing to ``scale``.

    The support is kept far below the degree so that products stay inside the basis
    (nothing is folded into the top degree) and the comparisons are exact.
    """
    rng = np.random.default_rng(seed)
    c = np.zeros(degree + 1)
    c[:support] = rng.uniform(0, 1, support)
    return PolyGaussian(jnp.asarray(scale * c / c.sum()), jnp.asarray(0.01))


def test_polynomial_multiplication_is_gaussian_convolution():
    """poly_multiply equals convolve on the same Gaussians (inside the degree)."""
    a, b = random_poly(0, 40, 0.6), random_poly(1, 40, 0.7)
    product = to_gaussian_sum(poly_multiply(a, b))
    k = np.geomspace(1e-2, 30, 40)
    expected = spectrum(convolve(to_gaussian_sum(a), to_gaussian_sum(b)), k)
    np.testing.assert_allclose(spectrum(product, k), expected, rtol=1e-12, atol=1e-14)
    assert float(poly_total(poly_multiply(a, b))) == pytest.approx(0.42, rel=1e-12)


def test_geometric_series_stops_within_its_energy_tolerance():
    """sum_m a^m has total 1/(1 - t) to within tol, and equals 1/(1 - a^) in frequency space."""
    a = random_poly(2, 2000, 0.9)
    series = geometric_series(a, tol=1e-6)
    assert float(poly_total(series)) == pytest.approx(1 / (1 - 0.9), abs=1e-6)
    k = np.geomspace(1e-2, 20, 30)
    np.testing.assert_allclose(spectrum(to_gaussian_sum(series), k), 1 / (1 - spectrum(to_gaussian_sum(a), k)),
                               atol=2e-6)


@pytest.mark.parametrize("max_terms", [1, 2, 5, 7, 11, 20])  # M + 1 = 6, 12, 21 read differently backwards
def test_geometric_series_by_doubling_equals_the_term_by_term_sum(max_terms):
    """The series is built by doubling; the sum 1 + a + ... + a^M one product at a time,
    with products that fold into the top degree (support 30 of degree 40), is the truth.
    Eager (M from the tolerance, capped by max_terms) and under jit (M = max_terms)."""
    from jsss.gaussians.poly_gaussians import PolyGaussian

    a = random_poly(3, 40, 0.95, support=30)
    power = PolyGaussian(jnp.zeros_like(a.coefficients).at[0].set(1.0), a.base_variance)
    expected = power
    for _ in range(max_terms):
        power = poly_multiply(power, a)
        expected = poly_add(expected, power)
    eager = geometric_series(a, tol=1e-12, max_terms=max_terms)
    traced = jax.jit(lambda p: geometric_series(p, max_terms=max_terms))(a)
    for got in (eager, traced):
        np.testing.assert_allclose(got.coefficients, expected.coefficients, rtol=1e-12, atol=1e-14)


def test_kubelka_munk_in_the_polynomial_basis_equals_frequency_space():
    """KM on exactly representable profiles: polynomial algebra = combine_spectra, to the tolerance."""
    from jsss.gaussians.poly_gaussians import _combine

    top = tuple(random_poly(s, 1000, f) for s, f in zip(range(4), (0.3, 0.6, 0.35, 0.6)))
    bottom = tuple(random_poly(s, 1000, f) for s, f in zip(range(4, 8), (0.5, 0.4, 0.45, 0.4)))
    combined = _combine(top, bottom, tol=1e-8)
    k = np.geomspace(1e-2, 20, 30)
    spec = lambda p: spectrum(to_gaussian_sum(p), k)  # noqa: E731
    expected = combine_spectra(tuple(spec(p) for p in top), tuple(spec(p) for p in bottom))
    for got, want in zip(combined, expected):
        np.testing.assert_allclose(spec(got), want, atol=1e-7)


def test_derived_pole_curves_sum_to_2pi_and_interpolate_the_derivation():
    """C_i(x) conserve the pole's power (sum 2 pi) and the table matches a fresh derivation."""
    for x in [0.0, 0.013, 0.37, 1.7, 9.3, 77.0]:
        derived, _ = derive_pole_weights(x)
        assert derived.sum() == pytest.approx(2 * np.pi, rel=1e-10)
        np.testing.assert_allclose(pole_weight_curves(x), derived, atol=5e-5)


def test_empirical_dipole_fit_within_3p5_percent_for_all_36_channels():
    """8 closed-form Gaussians fit every Fig. 5b channel with rel. RMS power error < 3.5 %
    (measured worst: Spectralon, 3.32 %) and reproduce the total reflectance exactly."""
    worst = 0.0
    for row in jensen2001_table():
        medium = jensen2001(row.name)
        gs = empirical_dipole_fit(medium)
        assert gs.n_terms == 24
        r = np.geomspace(1e-4 * float(np.min(medium.mean_free_path)), 1e3 * float(np.max(medium.mean_free_path)), 4000)
        errors = np.asarray(relative_rms_error(gs, r, dipole.profile(medium, r)))
        worst = max(worst, errors.max())
        np.testing.assert_allclose(total(gs), dipole.total_reflectance(medium), rtol=1e-9)
    assert worst < 0.035


def test_empirical_multipole_fit_totals_equal_the_slab_totals():
    """The pole fits conserve each pole's power, so the totals equal the (converged) multipole's."""
    medium = Medium(0.3, 1.5, 1.4)
    R, T = empirical_multipole_fit(medium, 0.8, n_dipoles=30)
    R_exact, T_exact = slab_totals(medium, 0.8)
    assert float(total(R)) == pytest.approx(float(R_exact), rel=1e-8)
    assert float(total(T)) == pytest.approx(float(T_exact), rel=1e-8)


def test_layers_in_the_gaussian_basis_agree_with_frequency_space_layers():
    """layers_as_gaussians vs jsss.layers.stack: totals within 1 % (measured <= 0.5 %); the
    profiles within 10 % of the total power in r-weighted L1 (measured 4-8.4 %), which is
    the error of the closed-form 4-Gaussian-per-pole fits, not of the KM algebra (that is
    checked exactly in test_kubelka_munk_in_the_polynomial_basis_equals_frequency_space)."""
    grid = hankel.hankel_grid()
    r = np.asarray(grid.r)
    for layers, base in [
        skin_three_layer(),
        ([Layer(Medium(0.3, 2.0, 1.4), 0.2), Layer(Medium(0.005, 1.5, 1.4), 3.0)], None),
    ]:
        R_poly, _ = layers_as_gaussians(layers, base)
        reference = stack(layers, base, grid=grid)
        np.testing.assert_allclose(poly_total(R_poly), reference.R_total, rtol=0.01)
        values = np.asarray(evaluate(to_gaussian_sum(R_poly), r)).reshape(r.size, -1)
        l1 = np.trapezoid(2 * np.pi * r[:, None] * np.abs(values - np.asarray(reference.R).reshape(r.size, -1)), r, axis=0)
        assert np.all(l1 < 0.10 * np.asarray(reference.R_total))


def test_gaussian_sum_rejects_bad_shapes_and_variances():
    with pytest.raises(ValueError, match="variances"):
        GaussianSum(jnp.ones(3), jnp.ones(2))
    with pytest.raises(ValueError, match=">= 0"):
        GaussianSum(jnp.ones(2), jnp.array([1.0, -1.0]))


def test_empirical_fit_is_differentiable():
    """grad of the fitted total and of a weight w.r.t. sigma_a is finite and the total's is exact."""
    g = jax.grad(lambda a: total(empirical_dipole_fit(Medium(a, 1.0, 1.3))))(0.05)
    exact = jax.grad(lambda a: dipole.total_reflectance(Medium(a, 1.0, 1.3)))(0.05)
    assert float(g) == pytest.approx(float(exact), rel=1e-6)
