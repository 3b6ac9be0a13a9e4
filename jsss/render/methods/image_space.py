r"""Image-space integration (Mertens et al. 2003 sec. 5-6): the exitance gathered per pixel from samples.

The irradiance is rendered once from the camera; each visible pixel integrates it against the
exact profile over ``samples`` points drawn in its tangent plane
(:func:`jsss.render.image_space.image_space_exitance`, where the algorithm and its variance
reduction are described). Noise falls like ``samples ** -0.5``.
"""

from __future__ import annotations

import numbers
from typing import ClassVar, final

import equinox as eqx

from ..image_space import SampledProfile, image_space_exitance, profile_radius
from ..passes import Method
from ..surface_maps import scaled
from .base import entry_irradiance
from .pixels import PixelMethod, PixelPrepared

__all__ = ["ImageSpace"]


@final
class ImageSpace(PixelMethod):
    """Mertens' image-space integration with ``samples`` per pixel.

    Attributes
    ----------
    samples : int >= 1
        Samples per pixel: the accuracy knob (the calibration table measures 8, 32, 128).
    uniform_fraction : float in [0, 1)
        Share of the samples drawn uniformly over a disc holding 95 % of the profile's light
        (sec. 6.1's combined sampling, for shadow borders).
    seed : int
        Picks the sample pattern's offset at each pixel; fixed, so a frame is a smooth function
        of the material (a fit's model).
    """

    method: ClassVar[Method] = Method.IMAGE_SPACE
    samples: int = eqx.field(default=32, static=True)
    uniform_fraction: float = eqx.field(default=0.25, static=True)
    seed: int = eqx.field(default=0, static=True)

    def __check_init__(self):
        if isinstance(self.samples, bool) or not isinstance(self.samples, numbers.Integral) or self.samples < 1:
            raise ValueError(f"ImageSpace(samples={self.samples!r}): samples per pixel must be a whole number >= 1 "
                             "(the calibration measures 8, 32 and 128); e.g. ImageSpace(samples=32).")
        if not (isinstance(self.uniform_fraction, numbers.Real) and 0 <= self.uniform_fraction < 1):
            raise ValueError(f"ImageSpace(uniform_fraction={self.uniform_fraction!r}) must lie in [0, 1): the share of "
                             "samples drawn uniformly over the disc (default 0.25).")
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral) or self.seed < 0:
            raise ValueError(f"ImageSpace(seed={self.seed!r}) must be a whole number >= 0.")
        if round(self.uniform_fraction * self.samples) >= self.samples:
            raise ValueError(f"ImageSpace(samples={self.samples}, uniform_fraction={self.uniform_fraction}) leaves no "
                             "importance samples; lower uniform_fraction or raise samples.")

    def prepare_own(self, scene, params, buffers, maps, timings):
        return None, profile_radius(self.sampling_profile(params))

    @staticmethod
    def sampling_profile(params) -> SampledProfile:
        """Where the samples are drawn: the material's profile, or with parameter maps the
        mixture of every basis node's profile, each normalised to its own light
        (:meth:`jsss.render.surface_maps.MapParams.node_mixture`). The material's own profile
        would serve a map of skin on a marble material badly: marble's long tail rarely lands
        in skin's core (32 samples: pixels 50-190 % off, unbiased but noisy)."""
        if params.maps is None or params.maps.node_weights is None:
            return params.profile
        return SampledProfile(weights=params.maps.node_mixture(), variances=params.variances)

    def exitance(self, params, prepared: PixelPrepared):
        """Mertens' estimate of :math:`M = \\int R(|x - y|) E(y)\\,dA_y` (H, W, C) [W/mm^2] per pixel."""
        dtype = params.radiant.dtype
        entry, exit_, coefficients = self.surface(params, prepared, dtype)
        E = entry_irradiance(params, prepared.lights, coefficients, entry)
        blend = None
        if coefficients is not None:  # Mertens: each sample's profile has the parameters at its entry point
            blend = (params.maps.node_weights.astype(dtype), params.variances)
            if params.maps.crosses():  # and light that leaves in another medium than it entered
                blend = blend + (coefficients, params.maps.node_crossing.astype(dtype))
        M = image_space_exitance(self.sampling_profile(params), E, prepared.buffers, samples=self.samples,
                                 uniform_fraction=self.uniform_fraction, disc_radius=prepared.disc_radius,
                                 seed=self.seed, entry_blend=blend)
        return scaled(M, exit_)

    def describe(self, plan) -> str:
        return f"{self.samples} samples per pixel"
