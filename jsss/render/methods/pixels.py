r"""What the three methods that shade from the camera's pixels share: Lambert, normal filtering, image-space.

All three start from the camera's G-buffer (:func:`jsss.render.camera_buffers`) and the lights'
shadows at its pixels, and end in the camera pass every method shares
(:func:`~jsss.render.methods.base.camera_radiance`). They differ only in how the exitance
:math:`M` arises from the irradiance (their :meth:`~PixelMethod.exitance`, each in its own file):

* :class:`~jsss.render.methods.Lambert` -- :math:`M = \rho E(x)`: the profile's total albedo, no spread;
* :class:`~jsss.render.methods.NormalFiltering` -- :math:`M_c = \rho_c E(x; n_c)` with per-channel
  filtered normals (Patro 2007);
* :class:`~jsss.render.methods.ImageSpace` -- :math:`M` by Mertens' integration (Mertens 2003).
"""

from __future__ import annotations

import abc
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax.numpy as jnp

from ..image_space import CameraBuffers
from ..memory import camera_key
from ..surface_maps import read_points
from .base import (
    PixelShading,
    PreparedGeometry,
    RenderMethod,
    camera_radiance,
    kept_camera,
    kept_lights,
    kept_shadow_maps,
    pixel_shading,
)

if TYPE_CHECKING:
    from ..planner import Plan
    from ..renderer import RenderParams
    from ..scene import Scene

__all__ = ["PixelMethod", "PixelPrepared"]


@dataclass(frozen=True, eq=False)
class PixelPrepared(PreparedGeometry):
    """Geometry-only data of a pixel method (NumPy).

    Attributes
    ----------
    buffers : CameraBuffers
    shading : PixelShading, the camera pass's data (its ``lights`` are the pixels' LightGeometry
        per light, with the true normals)
    channel_lights : tuple over channels of tuples over lights, with the filtered normals
        (normal filtering only, else None)
    disc_radius : float [mm], image-space's uniform disc (0 for the others)
    """

    buffers: CameraBuffers
    shading: PixelShading
    channel_lights: tuple | None = None
    disc_radius: float = 0.0

    @property
    def lights(self) -> tuple:
        return self.shading.lights


class PixelMethod(RenderMethod):
    """A method that shades from the camera's pixels (abstract); its frame is one stage."""

    def prepare(self, scene: Scene, plan: Plan, params: RenderParams, *,
                timings: dict | None = None) -> PixelPrepared:
        """Rasterize the camera view and the lights' shadows, then what the method itself needs."""
        timings = {} if timings is None else timings
        t0 = time.perf_counter()
        buffers = kept_camera(scene)  # each kept while the mesh, camera and lights' positions stay
        maps = kept_shadow_maps(scene)
        lights = kept_lights(scene, ("camera", camera_key(scene.camera)), buffers.position, buffers.normal,
                             buffers.mask, maps)
        timings["camera raster + shadows"] = time.perf_counter() - t0
        channel_lights, disc_radius = self.prepare_own(scene, params, buffers, maps, timings)
        return PixelPrepared(buffers, pixel_shading(scene, plan, buffers, lights), channel_lights, disc_radius)

    @abc.abstractmethod
    def prepare_own(self, scene: Scene, params: RenderParams, buffers: CameraBuffers, maps: list, timings: dict):
        """What only this method prepares: ``(channel_lights, disc_radius)`` (see :class:`PixelPrepared`)."""

    @staticmethod
    def surface(params: RenderParams, prepared: PixelPrepared, dtype):
        """What each pixel reads of the maps: ``(entry, exit, coefficients)``
        (:func:`jsss.render.surface_maps.read_points`)."""
        return read_points(params.maps, prepared.shading.colour_map, prepared.shading.coefficient_map, dtype)

    @staticmethod
    def reflected(params: RenderParams, E):
        r""":math:`\rho E` (H, W, C): the profile's total albedo times the entering light ``E``
        (:func:`~jsss.render.methods.base.entry_irradiance`); with parameter maps ``E`` holds
        :math:`a_k E_k` (H, W, K, C) and this is :math:`\sum_k \rho_k a_k E_k`."""
        if E.ndim == 3:
            return params.profile.albedo().astype(E.dtype) * E
        return jnp.einsum("...kc,kc->...c", E, params.maps.node_weights.sum(1).astype(E.dtype))

    def stages(self, prepared: PixelPrepared):
        return ((f"{self.method} frame", lambda params, _: camera_radiance(self.exitance(params, prepared), params,
                                                                           prepared.shading)),)

    def work(self, scene: Scene) -> int:
        return scene.camera.width * scene.camera.height
