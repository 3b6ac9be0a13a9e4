"""Kubelka-Munk stacks in frequency space: consistency, energy, splitting and gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium, dipole, hankel
from jsss.layers.kubelka_munk import Layer, skin_three_layer, stack, stack_spectra
from jsss.diffusion.multipole import slab_totals, unscattered_transmittance


@pytest.fixture(scope="module")
def grid():
    return hankel.hankel_grid()


def test_single_layer_stack_is_the_slab():
    """One layer in air: totals are slab_totals, the unscattered part carried in T."""
    m = Medium(0.05, 1.5, 1.4)
    R, T, _, _ = stack_spectra([Layer(m, 0.7)])
    R_slab, T_slab = slab_totals(m, 0.7)
    assert float(R) == pytest.approx(float(R_slab), rel=1e-14)
    assert float(T) == pytest.approx(float(T_slab + unscattered_transmittance(m, 0.7)), rel=1e-14)


def test_base_alone_is_the_dipole(grid):
    """No layers over a base: the stack's profile and total are the dipole's."""
    m = Medium(np.array([0.032, 0.17, 0.48]), np.array([0.74, 0.88, 1.01]), 1.3)
    result = stack([], m, grid=grid)
    np.testing.assert_allclose(result.R_total, dipole.total_reflectance(m), rtol=1e-14)
    peak = np.asarray(dipole.profile(m, 0.0))
    np.testing.assert_allclose(result.R, dipole.profile(m, grid.r), atol=1e-4 * peak.max())


def stacks():
    absorbing = Medium(0.02, 1.2, 1.4)
    clear = Medium(0.0, 2.0, 1.4)
    return {
        "two layers": ([Layer(absorbing, 0.3), Layer(Medium(0.3, 3.0, 1.33), 1.0)], None),
        "three over base": ([Layer(clear, 0.05), Layer(absorbing, 0.2), Layer(Medium(0.1, 0.9, 1.5), 0.5)],
                            Medium(0.01, 1.0, 1.4)),
        "skin": skin_three_layer(),
        "ten thin layers": ([Layer(Medium(0.01 * (i + 1), 1.0 + 0.2 * i, 1.3 + 0.02 * i), 0.1) for i in range(10)], None),
    }


@pytest.mark.parametrize("name", list(stacks()))
def test_reflectance_plus_transmittance_at_most_one(name):
    """R + T + unscattered <= 1 from above (and from below when defined); each >= 0."""
    layers, base = stacks()[name]
    R, T, R_up, T_up = stack_spectra(layers, base, 0.0)
    for x in (R, T, R_up, T_up):
        assert np.all(np.asarray(x) >= 0)
    assert np.all(np.asarray(R + T) <= 1 + 1e-12)
    assert np.all(np.asarray(R_up + T_up) <= 1 + 1e-12)


def test_non_absorbing_stack_conserves_energy():
    """sigma_a = 0 in every layer: R + T (with unscattered) = 1 both ways, to 1e-12."""
    layers = [Layer(Medium(0.0, 1.0 + i, 1.3 + 0.1 * i), 0.2 + 0.3 * i) for i in range(4)]
    R, T, R_up, T_up = stack_spectra(layers, None, 0.0)
    assert float(R + T) == pytest.approx(1.0, abs=1e-12)
    assert float(R_up + T_up) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("medium", [Medium(0.01, 1.0, 1.4), Medium(0.2, 3.0, 1.3), Medium(0.0, 2.0, 1.4),
                                    Medium(0.05, 0.8, 1.0)])
@pytest.mark.parametrize("d", [0.05, 0.2, 1.0, 4.0, 20.0])
def test_two_halves_equal_one_layer_within_005(medium, d):
    """Two layers of d/2 give the totals of one layer of d within 0.05 (absolute).

    Not exact: splitting inserts an index-matched boundary, which diffusion theory still
    treats as an extrapolated boundary (z_b = 2D). The worst measured difference is 0.046
    (T, sigma_a = 0.2, sigma_s' = 3, d = 1 mm); thin (d << mfp) and thick slabs agree to 1e-3.
    """
    one = stack_spectra([Layer(medium, d)])
    halves = stack_spectra([Layer(medium, d / 2), Layer(medium, d / 2)])
    for a, b in zip(one, halves):
        assert float(a) == pytest.approx(float(b), abs=0.05)
    if d <= 0.05 or d >= 20:
        assert float(one[0]) == pytest.approx(float(halves[0]), abs=1e-3)


def test_zero_thickness_layer_changes_nothing(grid):
    """A layer of thickness 0 (same index as its neighbour) leaves spectra and profiles unchanged."""
    layers, base = skin_three_layer()
    ghost = Layer(Medium(np.full(3, 0.5), np.full(3, 2.0), np.full(3, 1.4)), 0.0)
    with_ghost = [layers[0], layers[1], ghost]  # between epidermis and dermis, both n = 1.4
    np.testing.assert_allclose(stack_spectra(with_ghost, base, grid.k)[0], stack_spectra(layers, base, grid.k)[0],
                               rtol=1e-13, atol=1e-15)


def test_totals_equal_the_transform_of_the_profiles_at_k0(grid):
    """The profile's forward Hankel transform at the smallest k equals the closed-form total."""
    layers, base = skin_three_layer()
    result = stack(layers, base, grid=grid)
    np.testing.assert_allclose(hankel.forward(grid, result.R)[0], result.R_total, atol=1e-4)
    two = stack(stacks()["two layers"][0], grid=grid)
    np.testing.assert_allclose(hankel.forward(grid, two.T)[0], two.T_total, atol=1e-4)


def test_skin_preset_is_redder_than_blue():
    """Blood and melanin absorb blue most: skin reflects R > G > B, all within (0, 1)."""
    layers, base = skin_three_layer()
    R = np.asarray(stack_spectra(layers, base, 0.0)[0])
    assert np.all((0 < R) & (R < 1)) and R[0] > R[1] > R[2]


def _stack_totals(params):
    """Totals of a two-layer stack as a function of every layer parameter."""
    sa1, ss1, eta1, d1, sa2, ss2, eta2, d2 = params
    layers = [Layer(Medium(sa1, ss1, eta1), d1), Layer(Medium(sa2, ss2, eta2), d2)]
    R, T, R_up, T_up = stack_spectra(layers, None, 0.0)
    return jnp.stack([R, T, R_up, T_up])


@pytest.mark.parametrize(
    "params",
    [
        [0.05, 1.5, 1.4, 0.5, 0.2, 2.0, 1.3, 1.0],
        # Two thick, nearly non-absorbing slabs: R2+ R1- -> 1, the KM denominator -> 0.
        # (Indices differ: at a relative index of exactly 1 Fdr has a physical kink.)
        [1e-7, 5.0, 1.4, 200.0, 1e-7, 5.0, 1.3, 200.0],
    ],
)
def test_stack_gradients_are_finite_and_match_finite_differences(params):
    """d totals / d (sigma_a, sigma_s', eta, thickness) of each layer equals central differences."""
    x0 = np.array(params)
    if x0[3] > 100:  # the near-singular case: check that it is one
        top = Medium(*x0[:3])
        bottom = Medium(*x0[4:7])
        R1_up = slab_totals(top, x0[3], eta_top=x0[2] / x0[6], eta_bottom=x0[2])[0]
        R2_down = slab_totals(bottom, x0[7], eta_top=x0[6] / x0[2], eta_bottom=x0[6])[0]
        assert 0 < 1 - float(R1_up * R2_down) < 0.005
    jac = np.asarray(jax.jacobian(_stack_totals)(jnp.asarray(x0)))
    assert np.all(np.isfinite(jac))
    for j in range(x0.size):
        h = 1e-6 * max(abs(x0[j]), 1e-3)
        e = np.zeros_like(x0)
        e[j] = h
        numeric = (np.asarray(_stack_totals(jnp.asarray(x0 + e))) - np.asarray(_stack_totals(jnp.asarray(x0 - e)))) / (2 * h)
        np.testing.assert_allclose(jac[:, j], numeric, rtol=2e-4, atol=1e-6)


def test_bad_layers_are_rejected():
    """Negative thickness, a non-Layer entry, and an empty stack raise with a message."""
    with pytest.raises(ValueError, match="thickness"):
        Layer(Medium(0.1, 1.0), -0.1)
    with pytest.raises(TypeError, match="Layer"):
        stack_spectra([Medium(0.1, 1.0)], None, 0.0)
    with pytest.raises(ValueError, match="at least one"):
        stack_spectra([], None, 0.0)


def test_profiles_at_requested_radii_interpolate_the_grid(grid):
    """stack(..., r=...) returns the profile at those radii, equal to the dipole for a bare base."""
    m = Medium(0.02, 1.0, 1.4)
    r = jnp.array([0.05, 0.3, 1.0, 4.0])
    result = stack([], m, r=r, grid=grid)
    assert result.R.shape == (4,)
    np.testing.assert_allclose(result.R, dipole.profile(m, r), rtol=1e-4)
