"""The Monte Carlo random walk against adding-doubling, energy bookkeeping and its own tallies."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jsss import Medium
from jsss.transport.montecarlo import random_walk, sample_henyey_greenstein

iadpython = pytest.importorskip("iadpython")


@pytest.mark.parametrize(
    "albedo, g, n, b",
    [(0.9, 0.0, 1.0, 1.0), (0.99, 0.5, 1.4, 4.0), (0.8, 0.3, 1.33, 2.0)],
)
def test_slab_totals_agree_with_adding_doubling(albedo, g, n, b):
    """Total R and T of slabs within 3 standard errors + 0.002 (iadpython's own error with
    16 quadrature points at g <= 0.5) of adding-doubling. sigma_t = 1/mm, thickness b mm."""
    sample = iadpython.Sample(a=albedo, b=b, g=g, n=n, n_above=1.0, n_below=1.0, quad_pts=16)
    UR1, UT1, _, _ = sample.rt()
    rs = ((n - 1) / (n + 1)) ** 2
    result = random_walk(Medium(1 - albedo, albedo * (1 - g), n), thickness=b, g=g, n_photons=32768,
                         max_steps=1000, seed=1)
    # The walk starts inside (per unit entering flux): scale by the entry transmittance.
    # Both sides count the unscattered beam and its internal reflections.
    assert (1 - rs) * result.R == pytest.approx(UR1 - rs, abs=3 * result.R_err + 0.002)
    assert (1 - rs) * (result.T + result.T_unscattered) == pytest.approx(UT1, abs=3 * result.T_err + 0.002)
    # The unscattered beam: e^{-b} (1 - rs) per entering photon, with its internal echoes.
    echoes = (1 - rs) * np.exp(-b) / (1 - rs**2 * np.exp(-2 * b))
    assert result.T_unscattered == pytest.approx(echoes, abs=4 * np.sqrt(echoes / 32768))
    assert result.lost == 0.0


def test_non_absorbing_matched_half_space_reflects_everything_not_lost():
    """eta = 1, g = 0, sigma_a = 0: every photon leaves or is still walking: R + lost = 1."""
    result = random_walk(Medium(0.0, 1.0, 1.0), n_photons=8192, max_steps=2000, seed=2)
    assert result.R + result.lost == pytest.approx(1.0, abs=1e-12)
    assert result.lost < 0.05 and result.T == 0.0


def test_profile_integrates_to_the_total():
    """Sum over bins (0 to infinity) of profile x annulus area equals the total, R and T."""
    result = random_walk(Medium(0.05, 1.0, 1.3), thickness=3.0, n_photons=8192, seed=3)
    area = np.pi * np.diff(np.minimum(result.bin_edges, 1e150) ** 2)
    finite = np.isfinite(area)
    assert np.sum((result.R_profile * area)[finite]) == pytest.approx(result.R, rel=1e-12)
    assert np.sum((result.T_profile * area)[finite]) == pytest.approx(result.T, rel=1e-12)


def test_a_seed_reproduces_a_run_exactly():
    medium = Medium(0.1, 1.0, 1.3)
    a = random_walk(medium, n_photons=2048, seed=5)
    b = random_walk(medium, n_photons=2048, seed=5)
    c = random_walk(medium, n_photons=2048, seed=6)
    assert a.R == b.R and np.array_equal(a.R_profile, b.R_profile) and a.R != c.R


@pytest.mark.parametrize("g", [0.0, 0.5, -0.3, 0.9])
def test_henyey_greenstein_sampling_follows_its_cdf(g):
    """KS test of sampled cosines against the HG CDF, and their mean is g."""
    mu = np.asarray(sample_henyey_greenstein(g, jax.random.uniform(jax.random.PRNGKey(0), (20000,))))

    def cdf(x):
        if g == 0:
            return (x + 1) / 2
        return (1 - g**2) / (2 * g) * (1 / np.sqrt(1 + g**2 - 2 * g * x) - 1 / (1 + g))

    assert stats.kstest(mu, cdf).pvalue > 1e-3
    assert mu.mean() == pytest.approx(g, abs=4 * mu.std() / np.sqrt(mu.size))


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="single-channel"):
        random_walk(Medium(jnp.ones(3) * 0.1, 1.0))
    with pytest.raises(ValueError, match="g"):
        random_walk(Medium(0.1, 1.0), g=1.0)


def test_two_index_matched_halves_equal_one_slab():
    """Unlike diffusion theory, transport through two identical layers of d/2 is one slab of d:
    totals agree within 4 combined standard errors."""
    from jsss.layers.kubelka_munk import Layer
    from jsss.transport.montecarlo import random_walk_layers

    medium = Medium(0.05, 1.2, 1.4)
    one = random_walk_layers([Layer(medium, 2.0)], n_photons=16384, seed=1)
    two = random_walk_layers([Layer(medium, 1.0), Layer(medium, 1.0)], n_photons=16384, seed=2)
    for a, b, ea, eb in ((one.R, two.R, one.R_err, two.R_err), (one.T, two.T, one.T_err, two.T_err)):
        assert a == pytest.approx(b, abs=4 * np.hypot(ea, eb))


def test_non_absorbing_stack_with_index_steps_conserves_energy():
    """sigma_a = 0 in every layer, indices 1.3 / 1.5 / 1.33 over air: every photon is reflected,
    transmitted (scattered or not) or still walking."""
    from jsss.layers.kubelka_munk import Layer
    from jsss.transport.montecarlo import random_walk_layers

    layers = [Layer(Medium(0.0, 2.0, 1.3), 0.5), Layer(Medium(0.0, 0.5, 1.5), 1.0), Layer(Medium(0.0, 1.0, 1.33), 0.7)]
    result = random_walk_layers(layers, n_photons=8192, seed=4)
    assert result.R + result.T + result.T_unscattered + result.lost == pytest.approx(1.0, abs=1e-12)
    assert result.T_unscattered > 0 and result.lost < 1e-3
