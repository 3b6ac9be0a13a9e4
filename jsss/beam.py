r"""What a camera records of a narrow beam on a half space: the observable of a beam-profile
measurement (Jensen et al. 2001 sec. 4) under either profile model.

Closed-form physics shared by the fit (:func:`fitting.medium.fit_medium`) and the simulator
(:mod:`measure.synth`), so that the two cannot drift apart.
"""

from __future__ import annotations

import jax.numpy as jnp

from . import transport
from .diffusion import dipole
from .fresnel import exit_lobe

__all__ = ["observable", "plane_total"]


def plane_total(values, grid_r):
    """Whole-plane integral of a profile (r first): the trapezoid in log r of 2 pi r^2 f
    (the grid spans many decades)."""
    integrand = 2 * jnp.pi * (grid_r**2)[:, None] * values.reshape(grid_r.shape[0], -1)
    total = jnp.sum(0.5 * (integrand[1:] + integrand[:-1]) * jnp.diff(jnp.log(grid_r))[:, None], axis=0)
    return total.reshape(values.shape[1:])


def observable(model, g, view_cos, medium, k, grid_r, fixed=None):
    r"""The model's observable, and its whole-plane total, for one medium.

    For the dipole the values are the Hankel spectrum on ``k`` (closed form); for transport
    the profile on ``grid_r`` (the forward transform is folded into the fit's precomputed
    operators, :func:`fitting.medium.fit_medium`). The observable is the exitance per unit entering flux
    (``view_cos`` None), or the camera's radiance factor :math:`\pi (1 - F(0)) L(r, \theta)`:
    radiance toward the camera per unit *incident* flux, times pi (what a white-reference
    calibration of a camera image gives). ``fixed``: the transport tables already at the
    medium's eta and this observable (:func:`jsss.transport.fixed_slice`), as a fit holds them.
    """
    if view_cos is None:
        if model == "transport":
            values = (transport.profile(medium, grid_r, g=g) if fixed is None
                      else transport.slice_values(fixed, medium, grid_r))
            return values, transport.total_reflectance(medium, g=g)
        return dipole.spectrum(medium, k), dipole.total_reflectance(medium)
    entering = transport.entry_transmittance(medium.eta)
    if model == "transport":
        radiance = (transport.radiance(medium, grid_r, view_cos, g=g) if fixed is None
                    else transport.slice_values(fixed, medium, grid_r))
        values = jnp.pi * entering * radiance
        return values, plane_total(values, grid_r)
    factor = jnp.pi * entering * exit_lobe(view_cos, medium.eta)  # the diffusion exit law
    return dipole.spectrum(medium, k) * factor, dipole.total_reflectance(medium) * factor
