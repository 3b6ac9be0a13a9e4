"""The light's lateral steps below the surface (jsss.diffusion.lateral_step) against an
independent random walk (tests/truth/last_leg_walk.py: NumPy, no H function)."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss.diffusion.lateral_step import first_leg_step, last_leg_step
from jsss.medium import Medium
from tests.truth.last_leg_walk import exits

BINS = np.linspace(0.0, 1.0, 5)  # exit cosine bins


def _binned(walk, projection, predicted, first_bounce_apart):
    """Per exit-cosine bin: the walk's weighted mean of ``projection``, its standard error, and
    the formula's mean over the same photons (so the bin's width costs nothing)."""
    keep = walk["orders"] >= (2 if first_bounce_apart else 1)
    rows = []
    for lo, hi in itertools.pairwise(BINS):
        sel = keep & (walk["cos"] >= lo) & (walk["cos"] < hi)
        w = walk["weight"][sel]
        mean = np.sum(w * projection[sel]) / w.sum()
        error = np.sqrt(np.sum(w**2 * (projection[sel] - mean) ** 2)) / w.sum()
        rows.append((mean, error, np.sum(w * predicted[sel]) / w.sum()))
    return np.array(rows)


@pytest.mark.parametrize("albedo, cos_incident", [(0.1, 0.3), (0.75, 0.6), (0.98, 1.0)])
@pytest.mark.parametrize("first_bounce_apart", [False, True])
def test_both_legs_are_what_a_random_walk_measures(albedo, cos_incident, first_bounce_apart):
    """Each photon's displacement from entry to exit, projected on its exit direction's
    tangential part (the last leg) and on the beam's (the first leg), averaged per exit cosine:
    within 4 standard errors of the formulas in every bin (200k photons, 0.1-1.2 s)."""
    walk = exits(albedo, cos_incident, photons=200_000, seed=7)
    medium = Medium(1.0 - albedo, albedo, 1.0)  # extinction 1: steps in mean free paths
    along_exit = walk["x"] * walk["tx"] + walk["y"] * walk["ty"]
    last = np.asarray(last_leg_step(medium, cos_incident, walk["cos"], first_bounce_apart=first_bounce_apart))[:, 0]
    first = np.asarray(first_leg_step(medium, cos_incident, walk["cos"], first_bounce_apart=first_bounce_apart))[:, 0]
    for name, rows in (("last leg", _binned(walk, along_exit, last, first_bounce_apart)),
                       ("first leg", _binned(walk, walk["x"], first, first_bounce_apart))):
        z = (rows[:, 0] - rows[:, 2]) / rows[:, 1]
        assert np.all(np.abs(z) < 4), (name, rows, z)
    # The check can fail: single scattering's depth mu mu0 / (mu + mu0) alone is many errors off
    # where multiple scattering carries the light.
    if albedo > 0.5:
        mu, mu0 = np.maximum(walk["cos"], 1e-6), cos_incident
        single = np.sqrt(1 - mu**2) / mu * mu * mu0 / (mu + mu0)
        rows = _binned(walk, along_exit, single, first_bounce_apart)
        assert np.max(np.abs((rows[:, 0] - rows[:, 2]) / rows[:, 1])) > 10


def test_the_step_is_in_mm_and_tends_to_one_mean_free_path_at_grazing():
    """Lengths scale as 1/sigma_t'; toward the normal the step vanishes, at grazing it tends to
    the flight of one mean free path (tan(theta) <tau> -> 1/sigma_t')."""
    unit = Medium(jnp.array([0.25]), jnp.array([0.75]), 1.0)
    tenfold = Medium(jnp.array([2.5]), jnp.array([7.5]), 1.0)
    cosines = jnp.array([1.0, 0.7, 0.3, 1e-4])
    a, b = last_leg_step(unit, 0.8, cosines), last_leg_step(tenfold, 0.8, cosines)
    assert np.allclose(np.asarray(a), 10 * np.asarray(b), rtol=1e-12)
    assert abs(float(a[0, 0])) < 1e-12 and abs(float(a[-1, 0]) - 1.0) < 1e-2


def test_gradients_are_finite_at_albedo_zero_and_one_and_the_dtype_is_kept():
    """Albedo 0 with the first bounce apart returns nothing (0/0 in the kernel's slope); albedo 1
    is held below 1 as the H function holds it. float32 in, float32 out."""
    def total(sigma_s, apart):
        medium = Medium(1.0 - sigma_s, sigma_s, 1.3)
        return last_leg_step(medium, 0.7, jnp.array([0.9, 0.4]), first_bounce_apart=apart).sum()

    for value in (0.0, 1.0):
        for apart in (False, True):
            gradient = jax.grad(total)(jnp.asarray(value), apart)
            assert np.isfinite(float(gradient)), (value, apart)
    medium32 = Medium(jnp.float32(0.2), jnp.float32(0.8), 1.4)
    assert last_leg_step(medium32, 0.5, jnp.float32(0.5)).dtype == jnp.float32
