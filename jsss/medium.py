r"""The homogeneous scattering medium and the quantities derived from it."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .fresnel import diffuse_fresnel_reflectance, internal_reflection_parameter
from .numerics import as_float_array, format_value, is_concrete, safe_sqrt

__all__ = ["Medium", "reduced_albedo"]


def reduced_albedo(sigma_a, sigma_s_prime):
    r"""Reduced albedo :math:`\alpha' = \sigma_s' / (\sigma_a + \sigma_s')`.

    Parameters
    ----------
    sigma_a, sigma_s_prime : array_like, 1/mm (broadcast together)

    Returns
    -------
    alpha_prime : Array, dimensionless in [0, 1]; 0 where both are 0.
    """
    sigma_t = jnp.asarray(sigma_a) + sigma_s_prime
    ok = sigma_t > 0
    return jnp.where(ok, sigma_s_prime / jnp.where(ok, sigma_t, 1.0), 0.0)


def _check_nonnegative(name, value):
    array = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"Medium({name}=...) must be finite [1/mm]; got {format_value(value)}.")
    if np.any(array < 0):
        raise ValueError(f"Medium({name}=...) must be >= 0 [1/mm]; got {format_value(value)}.")


class Medium(eqx.Module):
    r"""A homogeneous translucent medium.

    Each field broadcasts against the others; put a channel axis last (e.g. RGB = 3).
    The medium is a pytree whose three fields are leaves, so ``jit``, ``vmap`` and
    ``grad`` reach every parameter, ``eta`` included.

    Parameters
    ----------
    sigma_a : array_like, 1/mm
        Absorption coefficient, >= 0.
    sigma_s_prime : array_like, 1/mm
        Reduced scattering coefficient :math:`\sigma_s' = \sigma_s (1 - g)`, >= 0.
    eta : array_like, default 1.3
        Index of refraction of the medium relative to the outside, > 0.

    Raises
    ------
    ValueError
        For concrete (non-traced) inputs: a negative or non-finite coefficient,
        ``eta <= 0``, or :math:`\sigma_t' = 0` (no interaction at all). Traced
        values are not checked.

    Examples
    --------
    >>> m = Medium(sigma_a=[0.0021, 0.0041, 0.0071], sigma_s_prime=[2.19, 2.62, 3.00], eta=1.5)
    >>> m.shape
    (3,)
    """

    sigma_a: jax.Array
    sigma_s_prime: jax.Array
    eta: jax.Array

    def __init__(self, sigma_a, sigma_s_prime, eta=1.3):
        if is_concrete((sigma_a, sigma_s_prime, eta)):
            _check_nonnegative("sigma_a", sigma_a)
            _check_nonnegative("sigma_s_prime", sigma_s_prime)
            eta_array = np.asarray(eta, dtype=float)
            if not np.all(np.isfinite(eta_array)) or np.any(eta_array <= 0):
                raise ValueError(
                    f"Medium(eta=...) must be finite and > 0 (the relative index of "
                    f"refraction, 1.3 for skin); got {format_value(eta)}."
                )
            total = np.asarray(sigma_a, dtype=float) + np.asarray(sigma_s_prime, dtype=float)
            if np.any(total == 0):
                raise ValueError(
                    "Medium(sigma_a=..., sigma_s_prime=...) must not both be 0 in a channel: "
                    f"sigma_t' = 0 means light never interacts; got sigma_a={format_value(sigma_a)}, "
                    f"sigma_s_prime={format_value(sigma_s_prime)}."
                )
        self.sigma_a = as_float_array(sigma_a)
        self.sigma_s_prime = as_float_array(sigma_s_prime)
        self.eta = as_float_array(eta)

    @property
    def shape(self) -> tuple[int, ...]:
        """Broadcast shape of the three parameters (the channel axes)."""
        return jnp.broadcast_shapes(
            jnp.shape(self.sigma_a), jnp.shape(self.sigma_s_prime), jnp.shape(self.eta)
        )

    @property
    def dtype(self):
        """Floating dtype the physics runs in (the promotion of the three fields)."""
        return jnp.result_type(self.sigma_a, self.sigma_s_prime, self.eta)

    @property
    def sigma_t_prime(self):
        r"""Reduced extinction :math:`\sigma_t' = \sigma_a + \sigma_s'` [1/mm]."""
        return self.sigma_a + self.sigma_s_prime

    @property
    def reduced_albedo(self):
        r"""Reduced albedo :math:`\alpha' = \sigma_s' / \sigma_t'` (dimensionless)."""
        return reduced_albedo(self.sigma_a, self.sigma_s_prime)

    @property
    def mean_free_path(self):
        r"""Reduced mean free path :math:`\ell = 1/\sigma_t'` [mm] (the dipole's real-source depth)."""
        return 1.0 / self.sigma_t_prime

    @property
    def diffusion_coefficient(self):
        r"""Diffusion coefficient :math:`D = 1 / (3 \sigma_t')` [mm]."""
        return 1.0 / (3.0 * self.sigma_t_prime)

    @property
    def sigma_tr(self):
        r"""Effective transport coefficient :math:`\sigma_{tr} = \sqrt{3 \sigma_a \sigma_t'}` [1/mm].

        Its derivative with respect to ``sigma_a`` is infinite at ``sigma_a = 0``;
        there it is returned large and finite (see :func:`jsss.numerics.safe_sqrt`).
        """
        return safe_sqrt(3.0 * self.sigma_a * self.sigma_t_prime)

    @property
    def diffuse_fresnel_reflectance(self):
        r""":math:`F_{dr}(\eta)`, the average diffuse Fresnel reflectance at the boundary."""
        return diffuse_fresnel_reflectance(self.eta)

    @property
    def internal_reflection(self):
        r""":math:`A = (1 + F_{dr}) / (1 - F_{dr})` (Jensen 2001 eq. 4)."""
        return internal_reflection_parameter(self.eta)
