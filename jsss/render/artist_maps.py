r"""The artist's maps -- total diffuse reflectance and mean free path -- as coefficient maps.

An artist paints a colour (the total diffuse reflectance :math:`R_d` a uniformly lit area
returns) and a translucency (the reduced mean free path :math:`\ell = 1/\sigma_t'` [mm]) per
texel. Each channel's :math:`R_d` fixes the reduced albedo :math:`\alpha'` through the
material's own profile model (the dipole's closed form, Jensen 2001 eq. 10 inverted by
:func:`jsss.diffusion.dipole.medium_from_reflectance`; or the transport tables' total,
inverted by interpolation on 4001 albedos, monotone), and then
:math:`\sigma_s' = \alpha'/\ell`, :math:`\sigma_a = (1 - \alpha')/\ell`. So a map rendered with
the material's profile model returns the painted :math:`R_d` under uniform light.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .. import transport
from ..diffusion import dipole
from ..medium import Medium

__all__ = ["coefficients_from_artist_maps"]


def _material_reflectance(medium: Medium, profile_model: str, g: float) -> np.ndarray:
    if profile_model == "transport":
        return np.asarray(transport.total_reflectance(medium, g=g), float)
    return np.asarray(dipole.total_reflectance(medium), float)


def _transport_albedo(total, eta, g):
    """Reduced albedo per value of ``total`` (..., 3) under the transport tables, by channel."""
    one_minus = np.geomspace(1e-6, 0.998, 4001)  # sigma_a / sigma_t' (the tables stop at sigma_a / sigma_s' = 999)
    alpha = np.empty_like(total)
    for c in range(total.shape[-1]):
        medium = Medium(jnp.asarray(one_minus), jnp.asarray(1 - one_minus), float(eta[c]))
        totals = np.asarray(transport.total_reflectance(medium, g=g), float)
        order = np.argsort(totals)
        if np.any(total[..., c] > totals.max() + 1e-9):
            raise ValueError(f"a diffuse reflectance of {total[..., c].max():.4g} in channel {c} is above the "
                             f"largest the transport tables reach at eta {eta[c]:g} ({totals.max():.4g}).")
        alpha[..., c] = 1 - np.interp(total[..., c], totals[order], one_minus[order])
    return alpha


def coefficients_from_artist_maps(medium: Medium, reflectance, mean_free_path, shape, *, profile_model: str = "dipole",
                                  g: float = 0.0):
    """``(sigma_a, sigma_s')`` maps [1/mm] of shape ``shape`` (H, W, 3) from an :math:`R_d` map and a
    mean-free-path map [mm] (either may be None: ``medium``'s own value then holds everywhere),
    under the material's profile model (``"dipole"`` or ``"transport"`` with HG ``g``).

    Raises ``ValueError`` for a reflectance the profile model cannot reach."""
    eta = np.broadcast_to(np.asarray(medium.eta, float), (3,))
    if reflectance is None:
        reflectance = np.broadcast_to(_material_reflectance(medium, profile_model, g), shape)
    if mean_free_path is None:
        sigma_t = np.asarray(medium.sigma_a, float) + np.asarray(medium.sigma_s_prime, float)
        mean_free_path = np.broadcast_to(1.0 / sigma_t, shape)
    reflectance, mean_free_path = np.asarray(reflectance, float), np.asarray(mean_free_path, float)
    if profile_model == "transport":
        alpha = _transport_albedo(reflectance, eta, g)
    else:
        if np.any(reflectance >= 1):
            raise ValueError("a diffuse reflectance must be below 1 (1 is a medium without absorption, "
                             "whose mean free path alone does not fix it).")
        alpha = np.asarray(dipole.reduced_albedo_from_reflectance(jnp.asarray(reflectance), jnp.asarray(eta))[0],
                           float)
    return (1 - alpha) / mean_free_path, alpha / mean_free_path
