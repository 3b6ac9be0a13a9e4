r"""Normal filtering (Patro 2007): the profile's blur folded into per-channel shading normals.

For Lambertian shading under distant light the irradiance is linear in the normal where it
is lit, so blurring the irradiance with the profile is blurring the normals
(:mod:`jsss.render.normal_filter` holds the filters). Each channel's normals are filtered
once per mesh and material in :meth:`NormalFiltering.prepare`; the frame then costs what
Lambert costs, :math:`M_c = \rho_c E(x; n_c)`, and no light crosses a shadow border (Patro's
noted limit).
"""

from __future__ import annotations

import numbers
import time
from typing import ClassVar, Literal, final

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ...diffusion.incidence import incidence_law
from ..image_space import SampledProfile, rms_radius
from ..lighting import light_geometry
from ..memory import camera_key, digest, kept, light_key, mesh_key
from ..mesh import weld
from ..normal_filter import laplacian_spectrum, smooth_normals, spectral_filter
from ..passes import Method
from ..raster import surface_attributes
from ..surface_maps import scaled
from .base import entry_irradiance
from .pixels import PixelMethod, PixelPrepared

__all__ = ["NORMAL_FILTERS", "NormalFiltering", "filtered_normals"]

NORMAL_FILTERS = ("spectral", "naive")


def filtered_normals(scene, profile: SampledProfile, *, kind: str = "spectral", eigenpairs: int = 128,
                     rms: float | None = None) -> np.ndarray:
    """Per-vertex normals filtered per channel (V, C, 3) for ``scene.mesh`` and ``profile``.

    ``spectral`` uses the profile's own transfer function (cut-off at its diffusion length);
    ``naive`` iterates Patro's neighbour mean until its spread matches ``rms`` [mm] (default:
    the profile's RMS radius), about ``(rms / edge)^2`` passes: each is a random-walk step of
    one edge.
    """
    mesh = scene.mesh
    if kind == "spectral":
        spectrum = laplacian_spectrum(mesh, eigenpairs)
        return spectral_filter(spectrum, mesh.normals, lambda w: np.asarray(profile.transfer(jnp.asarray(w))))
    if kind == "naive":
        positions, _, faces = weld(mesh)
        edge = float(np.linalg.norm(positions[faces[:, 0]] - positions[faces[:, 1]], axis=1).mean())
        rms = rms_radius(profile) if rms is None else rms
        iterations = int(np.clip(np.ceil((rms / edge) ** 2), 1, 400))
        if profile.medium is not None:
            sigma_tr = np.asarray(profile.medium.sigma_tr) * np.ones(3)
        else:  # a Gaussian sum has no sigma_tr: the one of a dipole as wide
            sigma_tr = np.full(3, 1.0 / max(rms, 1e-6))
        return smooth_normals(mesh, sigma_tr, iterations=iterations)
    raise ValueError(f"normal filter kind must be one of {', '.join(NORMAL_FILTERS)}; got {kind!r}.")


@final
class NormalFiltering(PixelMethod):
    """Patro's normal filtering: Lambert shading with per-channel normals blurred by the profile.

    Attributes
    ----------
    kind : {"spectral", "naive"}
        ``spectral``: the normals' expansion in the mesh Laplacian's eigenvectors, each
        coefficient scaled by the profile's transfer function (Patro eqs. 4-11); ``naive``:
        Patro's neighbour mean (eq. 3), iterated to the profile's RMS radius.
    eigenpairs : int >= 1
        Eigenvectors of the spectral filter.
    """

    method: ClassVar[Method] = Method.NORMAL_FILTERING
    kind: Literal["spectral", "naive"] = eqx.field(default="spectral", static=True)
    eigenpairs: int = eqx.field(default=128, static=True)

    def __check_init__(self):
        if self.kind not in NORMAL_FILTERS:
            raise ValueError(f"NormalFiltering(kind={self.kind!r}): the filter must be one of "
                             f"{', '.join(repr(k) for k in NORMAL_FILTERS)}; e.g. NormalFiltering(kind='spectral').")
        if isinstance(self.eigenpairs, bool) or not isinstance(self.eigenpairs, numbers.Integral) \
                or self.eigenpairs < 1:
            raise ValueError(f"NormalFiltering(eigenpairs={self.eigenpairs!r}) must be a whole number >= 1 "
                             "(default 128).")

    def prepare_own(self, scene, params, buffers, maps, timings):
        t0 = time.perf_counter()
        # Kept while the mesh, camera, lights' positions and the profile are the same (memory.py)
        key = (mesh_key(scene.mesh), camera_key(scene.camera), tuple(light_key(light) for light in scene.lights),
               scene.shadow_map_size, self.kind, self.eigenpairs, digest(params.profile))
        channel_lights = kept("filtered normals", key, lambda: self._channel_lights(scene, params, buffers, maps))
        timings["normal filter"] = time.perf_counter() - t0
        return channel_lights, 0.0

    def _channel_lights(self, scene, params, buffers, maps):
        """Each channel's lights at its filtered normals (a tuple over channels of tuples over lights)."""
        filtered = filtered_normals(scene, params.profile, kind=self.kind, eigenpairs=self.eigenpairs)
        raster, faces = buffers.raster, scene.mesh.faces
        # Two-sided shading turned some pixels' normals around: turn their filtered normals too.
        facing = np.sign((surface_attributes(raster, faces, scene.mesh.normals) * buffers.normal).sum(-1))
        channel_normals = [surface_attributes(raster, faces, filtered[:, c]) * facing[..., None]
                           for c in range(filtered.shape[1])]
        return tuple(tuple(light_geometry(buffers.position, normals, buffers.mask, light, m)
                           for light, m in zip(scene.lights, maps)) for normals in channel_normals)

    def exitance(self, params, prepared: PixelPrepared):
        """:math:`M_c = \\rho_c E(x; n_c)` (H, W, C) [W/mm^2]: each channel lit with its own filtered normals."""
        entry, exit_, coefficients = self.surface(params, prepared, params.radiant.dtype)
        law = None
        if params.oblique is not None and coefficients is None:
            law = incidence_law(params.oblique)  # one H solve for three channels
        channels = [entry_irradiance(params, lights, coefficients, entry, law=law)[..., c]
                    for c, lights in enumerate(prepared.channel_lights)]
        return scaled(self.reflected(params, jnp.stack(channels, -1)), exit_)

    def describe(self, plan) -> str:
        return f"{self.kind} filter"
