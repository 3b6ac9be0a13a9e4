"""The planner's NumPy paths equal the JAX functions they stand in for.

``incidence_ratio`` and ``single_scattering_share`` of a medium of numbers run in NumPy (the
planner calls them once per scene, and JAX lowered some 40 small programs for
them in every new process); under ``jit`` or ``grad`` they are the JAX functions. Truth: the
JAX path (checked against random walks in test_incidence.py and test_single_scattering.py)
to 1e-12, and Chandrasekhar's tabulated reflectances of the half space."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss.diffusion.incidence import incidence_law, incidence_ratio
from jsss.diffusion.single_scattering import (
    _single_and_diffuse,
    _single_and_diffuse_numpy,
    single_scattering_share,
)
from jsss.medium import Medium

MEDIA = [
    Medium([0.0032, 0.0017, 0.0048], [2.19, 2.62, 3.0], 1.5),   # marble: albedo near 1
    Medium([0.061, 0.97, 1.45], [0.18, 0.07, 0.03], 1.0),      # ketchup, index matched
    Medium(0.0, 1.0, 1.3),                                     # no absorption: albedo capped
    Medium(np.array([[0.1, 0.2, 0.3], [1.0, 2.0, 3.0]]), 1.0, [0.8, 1.0, 1.4]),  # basis nodes, eta < 1
]


@pytest.mark.parametrize("medium", MEDIA)
def test_incidence_ratio_in_numpy_is_the_jax_law(medium):
    for cos in (0.5, np.linspace(0.0, 1.0, 11), 1.0):
        fast = np.asarray(incidence_ratio(medium, cos))
        np.testing.assert_allclose(fast, np.asarray(incidence_law(medium)(cos)), rtol=0, atol=1e-12)
        assert fast.shape == np.shape(cos) + medium.shape


def test_incidence_ratio_keeps_a_float32_mediums_dtype_for_a_python_number():
    """A Python float is weakly typed in JAX: with float64 on, a float32 medium's ratio stays
    float32 on both paths (the NumPy path returned float64 until the review of 2026-12-04)."""
    medium = Medium(*(np.asarray(x, np.float32) for x in ([0.061, 0.97, 1.45], [0.18, 0.07, 0.03], [1.3] * 3)))
    fast, law = incidence_ratio(medium, 0.5), incidence_law(medium)(0.5)
    assert fast.dtype == law.dtype == jnp.float32
    np.testing.assert_allclose(fast, law, rtol=1e-5)


def test_incidence_ratio_under_jit_and_grad_is_the_jax_law():
    medium = MEDIA[1]
    traced = jax.jit(incidence_ratio)(medium, 0.5)
    np.testing.assert_allclose(traced, incidence_ratio(medium, 0.5), rtol=0, atol=1e-12)
    slope = jax.grad(lambda s: incidence_ratio(Medium(0.25, s, 1.0), 0.5))(0.75)
    h = 1e-6  # central difference of the NumPy path
    step = (incidence_ratio(Medium(0.25, 0.75 + h, 1.0), 0.5) - incidence_ratio(Medium(0.25, 0.75 - h, 1.0), 0.5))
    assert float(slope) == pytest.approx(float(step) / (2 * h), rel=1e-6)
    assert slope < 0  # nearer albedo 1 the slant matters less (marble 2 %, ketchup 30 %)


def test_incidence_ratio_against_chandrasekhar():
    """Albedo 0.75, index matched: A(mu) = 0.243, 0.283, 0.319 at mu = 1, 0.7, 0.5
    (Chandrasekhar 1960, ch. IV; the module's numbers, to their three digits)."""
    medium = Medium(0.25, 0.75, 1.0)
    ratio = np.asarray(incidence_ratio(medium, jnp.array([0.7, 0.5])))
    np.testing.assert_allclose(ratio, np.array([0.283, 0.319]) / 0.243, rtol=3e-3)


@pytest.mark.parametrize("medium", MEDIA + [Medium([1.0, 0.0], [0.5, 2.0], 0.7)])
def test_single_scattering_share_in_numpy_is_the_jax_program(medium):
    fast = _single_and_diffuse_numpy(medium)
    for mine, truth in zip(fast, _single_and_diffuse(medium)):
        np.testing.assert_allclose(mine, np.asarray(truth), rtol=1e-12, atol=1e-15)
        assert mine.shape == medium.shape
    single, diffusion = (np.asarray(a) for a in _single_and_diffuse(medium))
    np.testing.assert_allclose(single_scattering_share(medium), single / diffusion, rtol=1e-12)
