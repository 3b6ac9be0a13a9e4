"""The refilled-lane walk engine: its generator, its independence from scheduling, its records."""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium
from jsss.transport.montecarlo import random_walk
from jsss.transport.photon_walk import threefry_2x32, turn_cos_sin


@pytest.mark.parametrize(
    "key, counter, expected",
    [((0, 0), (0, 0), (0x6B200159, 0x99BA4EFE)),
     ((0xFFFFFFFF, 0xFFFFFFFF), (0xFFFFFFFF, 0xFFFFFFFF), (0x1CB996FC, 0xBB002BE7)),
     ((0x13198A2E, 0x03707344), (0x243F6A88, 0x85A308D3), (0xC4923A9C, 0x483DF7A0))],
)
def test_threefry_matches_random123_known_answers(key, counter, expected):
    """Known-answer vectors of Threefry-2x32-20 from Random123's kat_vectors."""
    out = threefry_2x32(tuple(jnp.uint32(k) for k in key), tuple(jnp.uint32(c) for c in counter))
    assert tuple(int(v) for v in out) == expected


def test_threefry_bits_are_uniform():
    """Chi-square of the top 4 bits over 2^16 counters: uniform within p > 1e-3."""
    from scipy import stats

    x0, x1 = threefry_2x32((jnp.uint32(7), jnp.uint32(0)), (jnp.arange(2**16, dtype=jnp.uint32), jnp.uint32(3)))
    for word in (x0, x1):
        counts = np.bincount(np.asarray(word) >> 28, minlength=16)
        assert stats.chisquare(counts).pvalue > 1e-3


@pytest.mark.parametrize("dtype, tolerance", [(jnp.float64, 1e-15), (jnp.float32, 3e-7)])
def test_turn_cos_sin_matches_numpy_over_the_whole_turn(dtype, tolerance):
    # The walk's uniforms are (bits + 0.5) 2^-32; add the quarter-turn boundaries, where the
    # polynomial pair is swapped and negated, and the ends.
    quarters = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    u = np.concatenate([(np.arange(0, 2**32, 2**32 // 200003, dtype=np.float64) + 0.5) * 2.0**-32,
                        quarters, np.nextafter(quarters, 2), np.nextafter(quarters, -1)[1:]])
    u = np.clip(u, 0, 1).astype(dtype)
    cos, sin = turn_cos_sin(jnp.asarray(u))
    angle = 2 * np.pi * u.astype(np.float64)
    assert cos.dtype == dtype
    assert np.max(np.abs(np.asarray(cos, np.float64) - np.cos(angle))) < tolerance
    assert np.max(np.abs(np.asarray(sin, np.float64) - np.sin(angle))) < tolerance
    assert np.max(np.abs(np.hypot(np.asarray(cos, np.float64), np.asarray(sin, np.float64)) - 1)) < tolerance


def test_result_does_not_depend_on_the_lane_count():
    """Counter-based numbers: the same seed gives bit-identical tallies with 64 or 1024 lanes,
    although lanes finish and refill in a different order."""
    medium = Medium(0.01, 1.0, 1.4)
    a = random_walk(medium, n_photons=3000, batch_size=64, seed=4, progress=False)
    b = random_walk(medium, n_photons=3000, batch_size=1024, seed=4, progress=False)
    assert a.R == b.R and np.array_equal(a.R_profile, b.R_profile)


def test_every_photon_is_recorded_once_and_none_is_cut_short():
    """At albedo 0.999 walks run to thousands of events; with no cap no photon is lost, and
    the reflectance plus the absorbed share (roulette) accounts for every photon."""
    from jsss.transport.montecarlo import _params
    from jsss.transport.photon_walk import run_walk

    medium = Medium(0.001, 0.999, 1.3)
    records = run_walk(_params([medium], [np.inf], g=0.0, eta_above=1 / 1.3, eta_below=1 / 1.3, relative=True),
                       n_photons=5000, lanes=256, max_steps=10**7, seed=1, progress=False)
    assert records.radius.shape == (5000,)
    assert set(np.unique(records.side)) <= {1, 3}
    left = records.side == 1
    assert np.all(records.path[left] > 0) and np.all((records.exit_cos[left] > 0) & (records.exit_cos[left] <= 1))


def test_defaults_cut_no_photon_short_at_high_albedo():
    """The old default cap of 2000 events lost 5.7 % of the photons at albedo 0.999; with
    refilled lanes the default cap is 10^6 and none is lost."""
    result = random_walk(Medium(0.001, 0.999, 1.3), n_photons=2000, seed=8, progress=False)
    assert result.lost == 0.0
