r"""The BRDF approximation of the BSSRDF for uniform illumination (Jensen et al. 2001 sec. 2.4).

.. math:: f_r(\omega_i, \omega_o) = f_r^{(1)}(\omega_i, \omega_o) + F\,\frac{R_d}{\pi},
    \qquad F = F_t(\eta, \omega_i)\,F_t(\eta, \omega_o)

with :math:`f_r^{(1)}` the single-scattering BRDF and :math:`R_d` the dipole's total
diffuse reflectance. Useful for opaque materials whose mean free path is below a pixel.
"""

from __future__ import annotations

import jax.numpy as jnp

from .dipole import total_reflectance
from ..fresnel import fresnel_transmittance
from ..medium import Medium
from ..numerics import append_axes, as_float_array
from .single_scattering import single_scattering_brdf

__all__ = ["brdf", "diffuse_brdf"]


def diffuse_brdf(medium: Medium, omega_i, omega_o):
    r"""Multiple-scattering part :math:`F R_d / \pi` [1/sr]; shapes as in :func:`brdf`."""
    n = len(medium.shape)
    cos_i = append_axes(as_float_array(omega_i)[..., 2], n)
    cos_o = append_axes(as_float_array(omega_o)[..., 2], n)
    fresnel = fresnel_transmittance(cos_i, medium.eta) * fresnel_transmittance(cos_o, medium.eta)
    return fresnel * total_reflectance(medium) / jnp.pi


def brdf(medium: Medium, omega_i, omega_o, *, g=0.0):
    r"""Full BRDF approximation: single scattering plus :math:`F R_d/\pi` [1/sr].

    Parameters
    ----------
    medium : Medium
        Of shape ``C``.
    omega_i, omega_o : array_like, shape ``S + (3,)``
        Unit directions towards the light and the viewer, normal along +z.
    g : float, keyword-only
        Henyey-Greenstein mean cosine of the single-scattering term, in (-1, 1).

    Returns
    -------
    f_r : Array of shape ``S + C``, symmetric in ``omega_i`` and ``omega_o``.
    """
    return single_scattering_brdf(medium, omega_i, omega_o, g=g) + diffuse_brdf(
        medium, omega_i, omega_o
    )
