"""Medium: derived quantities, eager validation of concrete inputs, pytree behaviour."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium


def test_derived_quantities_match_their_definitions():
    """Every property equals its formula from Jensen 2001 sec. 2 for an RGB medium."""
    sa, ss, eta = np.array([0.0021, 0.0041, 0.0071]), np.array([2.19, 2.62, 3.00]), 1.5
    m = Medium(sa, ss, eta)
    st = sa + ss
    fdr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    np.testing.assert_allclose(m.sigma_t_prime, st, rtol=1e-15)
    np.testing.assert_allclose(m.reduced_albedo, ss / st, rtol=1e-15)
    np.testing.assert_allclose(m.sigma_tr, np.sqrt(3 * sa * st), rtol=1e-15)
    np.testing.assert_allclose(m.diffusion_coefficient, 1 / (3 * st), rtol=1e-15)
    np.testing.assert_allclose(m.mean_free_path, 1 / st, rtol=1e-15)
    np.testing.assert_allclose(m.diffuse_fresnel_reflectance, fdr, rtol=1e-15)
    np.testing.assert_allclose(m.internal_reflection, (1 + fdr) / (1 - fdr), rtol=1e-15)
    assert m.shape == (3,)


@pytest.mark.parametrize(
    "kwargs, names",
    [
        (dict(sigma_a=-0.1, sigma_s_prime=1.0), ["sigma_a", "-0.1"]),
        (dict(sigma_a=0.1, sigma_s_prime=[1.0, -2.0, 1.0]), ["sigma_s_prime", "-2.0"]),
        (dict(sigma_a=0.1, sigma_s_prime=1.0, eta=0.0), ["eta", "0.0"]),
        (dict(sigma_a=0.1, sigma_s_prime=1.0, eta=-1.3), ["eta", "-1.3"]),
        (dict(sigma_a=[0.0, 0.1], sigma_s_prime=[0.0, 1.0]), ["sigma_t' = 0"]),
        (dict(sigma_a=float("nan"), sigma_s_prime=1.0), ["sigma_a", "finite"]),
    ],
)
def test_bad_concrete_parameters_raise_naming_the_parameter(kwargs, names):
    """Invalid concrete inputs raise ValueError whose message names parameter and value."""
    with pytest.raises(ValueError) as info:
        Medium(**kwargs)
    for name in names:
        assert name in str(info.value)


def test_traced_values_are_not_validated():
    """Inside jit the values are unknown, so construction does not check them."""
    out = jax.jit(lambda a: Medium(a, 1.0).sigma_t_prime)(-0.5)
    assert float(out) == pytest.approx(0.5)


def test_medium_is_a_pytree_for_jit_vmap_and_grad():
    """jit, vmap over a batch of media, and grad w.r.t. every field all work."""
    media = Medium(jnp.array([0.01, 0.1, 1.0]), jnp.array([1.0, 2.0, 3.0]), jnp.array([1.3, 1.4, 1.5]))
    albedo = jax.vmap(lambda m: m.reduced_albedo)(media)
    np.testing.assert_allclose(albedo, [1 / 1.01, 2 / 2.1, 3 / 4], rtol=1e-14)
    grads = jax.grad(lambda m: m.internal_reflection + m.sigma_tr)(Medium(0.1, 1.0, 1.3))
    assert all(np.isfinite(float(g)) for g in (grads.sigma_a, grads.sigma_s_prime, grads.eta))
    assert float(jax.jit(lambda m: m.mean_free_path)(Medium(0.5, 1.5))) == pytest.approx(0.5)


def test_integer_inputs_become_floats_and_float32_is_kept():
    """Ints become the default float; float32 inputs keep float32 (no silent upcast)."""
    assert jnp.issubdtype(Medium(0, 1, 1).sigma_a.dtype, jnp.floating)
    m32 = Medium(np.float32(0.1), np.float32(1.0), np.float32(1.3))
    assert m32.dtype == jnp.float32


def test_bad_values_are_quoted_as_values_not_as_array_reprs():
    """A jnp array in an error message reads as the numbers (before: `Array([nan, ...], dtype=...)`)."""
    import jax.numpy as jnp

    with pytest.raises(ValueError) as info:
        Medium(0.1, 1.0, jnp.array([jnp.nan, 1.3], jnp.float32))
    assert "got [nan, 1.3]." in str(info.value) and "Array" not in str(info.value)
