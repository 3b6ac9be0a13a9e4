r"""Lambert: the profile's total albedo times the irradiance, no spread (no knobs).

:math:`M(x) = \rho\,E(x)` with :math:`\rho = 2\pi\int_0^\infty R(r)\,r\,dr` the profile's total
diffuse reflectance: right when the profile is smaller than a pixel, the planner's choice for
a far or small object (the calibration table measures where).
"""

from __future__ import annotations

from typing import ClassVar, final

from ..passes import Method
from ..surface_maps import scaled
from .base import entry_irradiance
from .pixels import PixelMethod, PixelPrepared

__all__ = ["Lambert"]


@final
class Lambert(PixelMethod):
    """Total albedo times the irradiance at each pixel: :math:`M = \\rho E`. No knobs."""

    method: ClassVar[Method] = Method.LAMBERT

    def prepare_own(self, scene, params, buffers, maps, timings):
        return None, 0.0

    def exitance(self, params, prepared: PixelPrepared):
        """:math:`\\rho E` (H, W, C) [W/mm^2]; the irradiance scaled by the oblique-incidence law and
        read at the deposit depth where ``params`` carry those media. With maps, :math:`\\rho E` is
        blended from the basis nodes' (each lit by its own law) and the colour map multiplies on
        entry and exit."""
        entry, exit_, coefficients = self.surface(params, prepared, params.radiant.dtype)
        return scaled(self.reflected(params, entry_irradiance(params, prepared.lights, coefficients, entry)), exit_)

    def describe(self, plan) -> str:
        return "none"
