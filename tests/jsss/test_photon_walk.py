"""The refilled-lane walk engine: its generator, its independence from scheduling, its records."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium
from jsss.transport.montecarlo import random_walk
from jsss.transport.photon_walk import _event_words, turn_cos_sin

_MASK = 0xFFFFFFFF


def _threefry_reference(key, counter):
    """Threefry-2x32-20 (Salmon et al. 2011) in plain Python integers: the test's own truth."""
    ks = (key[0], key[1], key[0] ^ key[1] ^ 0x1BD11BDA)
    x0, x1 = (counter[0] + ks[0]) & _MASK, (counter[1] + ks[1]) & _MASK
    rotations = (13, 15, 26, 6, 17, 29, 16, 24)
    for group in range(5):
        for r in rotations[4 * (group % 2): 4 * (group % 2) + 4]:
            x0 = (x0 + x1) & _MASK
            x1 = (((x1 << r) | (x1 >> (32 - r))) & _MASK) ^ x0
        x0 = (x0 + ks[(group + 1) % 3]) & _MASK
        x1 = (x1 + ks[(group + 2) % 3] + group + 1) & _MASK
    return x0, x1


_KNOWN_ANSWERS = [((0, 0), (0, 0), (0x6B200159, 0x99BA4EFE)),
                  ((0xFFFFFFFF, 0xFFFFFFFF), (0xFFFFFFFF, 0xFFFFFFFF), (0x1CB996FC, 0xBB002BE7)),
                  ((0x13198A2E, 0x03707344), (0x243F6A88, 0x85A308D3), (0xC4923A9C, 0x483DF7A0))]


@pytest.mark.parametrize("key, counter, expected", _KNOWN_ANSWERS)
def test_reference_threefry_matches_random123_known_answers(key, counter, expected):
    """Known-answer vectors of Threefry-2x32-20 from Random123's kat_vectors: the reference
    the walk's words are checked against below is itself right."""
    assert _threefry_reference(key, counter) == expected


@pytest.mark.parametrize("key, counter, expected", _KNOWN_ANSWERS[1:])
def test_event_words_are_random123_blocks_at_the_events_counters(key, counter, expected):
    """Event k of photon i draws (x0, x1) of the block at counter (i, 2k), then (x0, x1) of
    (i, 2k + 1): the first two words are Random123's known answers (an odd counter is the
    second block of event (c - 1) / 2), all four equal the reference."""
    photon, word = counter
    steps, first = word // 2, word % 2 == 0
    words = [int(w) for w in _event_words(tuple(jnp.uint32(k) for k in key), jnp.int64(photon), jnp.int64(steps))]
    assert tuple(words[:2] if first else words[2:]) == expected
    assert tuple(words) == (_threefry_reference(key, (photon, 2 * steps))
                            + _threefry_reference(key, (photon, 2 * steps + 1)))


def test_event_words_match_the_reference_under_vmap():
    """The walk calls the generator per lane under ``vmap``: the same words as the reference,
    photon by photon, for a key with both halves set."""
    rng = np.random.default_rng(5)
    key = (0x9E3779B9, 0x7F4A7C15)
    photons = rng.integers(0, 2**31 - 1, 64)
    steps = rng.integers(0, 10**6, 64)
    words = jax.vmap(_event_words, in_axes=(None, 0, 0))(tuple(jnp.uint32(k) for k in key),
                                                         jnp.asarray(photons, jnp.int32), jnp.asarray(steps, jnp.int32))
    expected = [_threefry_reference(key, (int(i), 2 * int(k))) + _threefry_reference(key, (int(i), 2 * int(k) + 1))
                for i, k in zip(photons, steps)]
    assert np.array_equal(np.asarray(words), np.array(expected, dtype=np.uint32))


def test_event_words_are_uniform():
    """Chi-square of the top 4 bits of each of the four words over 2^14 photons: uniform
    within p > 1e-3."""
    from scipy import stats

    words = jax.vmap(_event_words, in_axes=(None, 0, None))((jnp.uint32(7), jnp.uint32(0)),
                                                            jnp.arange(2**14, dtype=jnp.int32), jnp.int32(3))
    for word in np.asarray(words).T:
        counts = np.bincount(word >> 28, minlength=16)
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
