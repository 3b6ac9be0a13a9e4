r"""What a calibrated beam-profile image holds under a profile model: the forward model that the
simulator (:mod:`measure.synth`) draws images from and that the fit's plot and residuals
(:attr:`measure.pipeline.MeasurementFit.fitted_bins`) compare with, so the two cannot drift apart.
It is :func:`jsss.beam.observable`, the fit's own, convolved with the Gaussian beam.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from fitting.programs import reusable_program
from jsss import transport
from jsss.beam import observable
from jsss.diffusion import dipole
from jsss.layers import hankel
from jsss.medium import Medium

__all__ = ["diffuse_reflectance", "observed"]


def observed(medium: Medium, radii_mm: np.ndarray, beam_sigma_mm: float, grid=None, *, model="transport", g=0.0,
              view_angle_deg=0.0) -> np.ndarray:
    """What the calibrated image holds (exitance, or pi (1 - F(0)) L toward the camera), the
    model convolved with the Gaussian beam, at the given radii: shape radii.shape + C."""
    grid = hankel.hankel_grid() if grid is None else grid
    if model == "transport":
        transport.check_medium(medium, g=g)  # the evaluation below is jitted, where it cannot check
    view_cos = None if view_angle_deg is None else float(np.cos(np.radians(view_angle_deg)))
    radii_mm = np.asarray(radii_mm, dtype=float)
    values = _beam_convolved(medium, grid, jnp.asarray(beam_sigma_mm, grid.r.dtype), radii_mm, model=model, g=float(g),
                             view_cos=view_cos)
    return np.asarray(values).reshape(radii_mm.shape + (-1,))


# One program, not some sixty eager operations compiled one by one (8 s of fit-params --demo).
@reusable_program(static_argnames=("model", "g", "view_cos"))
@partial(jax.jit, static_argnames=("model", "g", "view_cos"))
def _beam_convolved(medium, grid, beam_sigma_mm, radii_mm, *, model, g, view_cos):
    # The fit's own forward model (jsss.beam.observable), so the two cannot drift apart:
    # a spectrum for the dipole, a profile on the transform grid for transport.
    values, _ = observable(model, g, view_cos, medium, grid.k, grid.r)
    spectrum = values.reshape(grid.k.shape[0], -1)
    if model == "transport":
        spectrum = grid.forward_matrix @ spectrum
    spectrum = spectrum * jnp.exp(-grid.k[:, None] ** 2 * beam_sigma_mm**2 / 2)
    return hankel.at_radii(grid, hankel.inverse(grid, spectrum), radii_mm)


@reusable_program(static_argnames=("model", "g"))
@partial(jax.jit, static_argnames=("model", "g"))
def diffuse_reflectance(medium: Medium, *, model: str = "transport", g: float = 0.0):
    r"""The medium's total diffuse reflectance :math:`R_d`: the exitance over the whole plane per
    unit *entering* flux under the model (the transport tables' total, or the dipole's, Jensen 2001
    eq. 5), the quantity published tables list. Not the plane total of a camera's radiance factor
    :math:`\pi (1 - F(0)) L`, which a white-reference calibration of an image sums to (0.8494
    against 0.8384 for marble's red). Jitted: eagerly, the tables' interpolation is some sixty
    small programs (4 s)."""
    return transport.total_reflectance(medium, g=g) if model == "transport" else dipole.total_reflectance(medium)
