r"""What a camera records of a narrow beam on a half space: the observable of a beam-profile
measurement (Jensen et al. 2001 sec. 4) under either profile model.

Closed-form physics shared by the fit (:func:`fitting.medium.fit_medium`) and the simulator
(:mod:`measure.synth`), so that the two cannot drift apart.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from . import transport
from .diffusion import dipole
from .fresnel import exit_lobe

__all__ = ["observable", "plane_total"]


def plane_total(values, grid_r):
    """Whole-plane integral of a profile (r first): the trapezoid in log r of 2 pi r^2 f
    (the grid spans many decades), plus the core r < r[0] at the first value, as the Hankel
    transform's product integration takes it (:func:`jsss.layers.hankel.hankel_grid`)."""
    flat = values.reshape(grid_r.shape[0], -1)
    integrand = 2 * jnp.pi * (grid_r**2)[:, None] * flat
    total = jnp.sum(0.5 * (integrand[1:] + integrand[:-1]) * jnp.diff(jnp.log(grid_r))[:, None], axis=0)
    total = total + jnp.pi * grid_r[0] ** 2 * flat[0]
    return total.reshape(values.shape[1:])


# Gauss-Legendre in s = (r / r[0])^2 on [0, 1]: the mean of a profile over the grid's core disc.
_CORE_NODES, _CORE_WEIGHTS = np.polynomial.legendre.leggauss(8)
_CORE_S, _CORE_W = (_CORE_NODES + 1) / 2, _CORE_WEIGHTS / 2


def _on_grid(evaluate, grid_r):
    """``evaluate`` (radii -> S + C) on ``grid_r``, its first value replaced by the profile's
    mean over the core r < r[0].

    The transform pair and :func:`plane_total` take a profile as flat on that core, at its
    first value. The transport tables' inner disc (rho' < 1e-3) is not flat: toward the
    normal it holds the beam's single scattering, a bump up to 10^4 times its rim, and at
    marble's sigma_s' (2-3 /mm) the disc's edge lies at 3-5 times r[0] = 1e-4 mm. Read at
    r[0], the core lost 1e-4 of the plane total, and the beam-convolved image near the beam
    read 0.4-1.1 % low (against quadrature, and against the same medium scaled 10 times, whose
    disc the grid resolves)."""
    core_r = grid_r[0] * jnp.sqrt(jnp.asarray(_CORE_S, grid_r.dtype))
    both = evaluate(jnp.concatenate([grid_r, core_r]))
    n = grid_r.shape[0]
    core_mean = jnp.tensordot(jnp.asarray(_CORE_W, both.dtype), both[n:], axes=1)
    return both[:n].at[0].set(core_mean)


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
            values = _on_grid(lambda r: transport.profile(medium, r, g=g) if fixed is None
                              else transport.slice_values(fixed, medium, r), grid_r)
            return values, transport.total_reflectance(medium, g=g)
        return dipole.spectrum(medium, k), dipole.total_reflectance(medium)
    entering = transport.entry_transmittance(medium.eta)
    if model == "transport":
        radiance = _on_grid(lambda r: transport.radiance(medium, r, view_cos, g=g) if fixed is None
                            else transport.slice_values(fixed, medium, r), grid_r)
        values = jnp.pi * entering * radiance
        return values, plane_total(values, grid_r)
    factor = jnp.pi * entering * exit_lobe(view_cos, medium.eta)  # the diffusion exit law
    return dipole.spectrum(medium, k) * factor, dipole.total_reflectance(medium) * factor
