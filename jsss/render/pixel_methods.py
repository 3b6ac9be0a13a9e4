"""The three methods that shade from the camera's pixels: Lambert, normal filtering, image-space.

All three start from the camera's G-buffer (:func:`camera_buffers`) and end like the
texture-space path: exitance :math:`M` -> :func:`diffuse_radiance` (+ specular). They
differ in how :math:`M` arises from the irradiance:

* ``lambert`` -- :math:`M = \\rho E(x)`: the profile's total albedo, no spread (right when the
  profile is smaller than a pixel);
* ``normal filtering`` -- :math:`M_c = \\rho_c E(x; n_c)` with per-channel filtered normals
  (Patro 2007, :mod:`.normal_filter`): a blurred look at Lambert's cost, no light across
  shadow borders;
* ``image-space`` -- :math:`M` by Mertens' integration (:mod:`.image_space`), noise falling
  with the samples per pixel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ..diffusion.incidence import incidence_law
from .image_space import (CameraBuffers, SampledProfile, camera_buffers, image_space_exitance, profile_radius,
                          rms_radius)
from .lighting import irradiance, light_geometry, shadow_map
from .mesh import weld
from .normal_filter import laplacian_spectrum, smooth_normals, spectral_filter
from .passes import Method
from .raster import surface_attributes
from .scene import Scene
from .shading import specular_radiance, surface_radiance

__all__ = ["PixelPrepared", "filtered_normals", "pixel_exitance", "pixel_radiance", "prepare_pixels"]


@dataclass(frozen=True, eq=False)
class PixelPrepared:
    """Geometry-only data of a pixel method (NumPy).

    Attributes
    ----------
    buffers : CameraBuffers
    lights : tuple of LightGeometry per light (true normals)
    channel_lights : tuple over channels of tuples over lights, with the filtered normals
        (normal filtering only, else None)
    disc_radius : float [mm], image-space's uniform disc
    """

    buffers: CameraBuffers
    lights: tuple
    channel_lights: tuple | None
    disc_radius: float


def filtered_normals(scene: Scene, profile: SampledProfile, *, kind: str = "spectral", eigenpairs: int = 128,
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
    raise ValueError(f"normal filter kind must be 'spectral' or 'naive'; got {kind!r}.")


def prepare_pixels(scene: Scene, method: str, profile: SampledProfile, *, normal_filter: str = "spectral",
                   eigenpairs: int = 128, timings: dict | None = None) -> PixelPrepared:
    """Rasterize the camera view and the lights' shadows; filter the normals if ``method`` needs them."""
    timings = {} if timings is None else timings
    t0 = time.perf_counter()
    buffers = camera_buffers(scene.mesh, scene.camera)
    maps = [shadow_map(scene.mesh, light, size=scene.shadow_map_size) for light in scene.lights]
    lights = tuple(light_geometry(buffers.position, buffers.normal, buffers.mask, light, m)
                   for light, m in zip(scene.lights, maps))
    timings["camera raster + shadows"] = time.perf_counter() - t0
    channel_lights = None
    if method == Method.NORMAL_FILTERING:
        t0 = time.perf_counter()
        filtered = filtered_normals(scene, profile, kind=normal_filter, eigenpairs=eigenpairs)
        raster, faces = buffers.raster, scene.mesh.faces
        # Two-sided shading turned some pixels' normals around: turn their filtered normals too.
        facing = np.sign((surface_attributes(raster, faces, scene.mesh.normals) * buffers.normal).sum(-1))
        channel_normals = [surface_attributes(raster, faces, filtered[:, c]) * facing[..., None]
                           for c in range(filtered.shape[1])]
        channel_lights = tuple(tuple(light_geometry(buffers.position, normals, buffers.mask, light, m)
                                     for light, m in zip(scene.lights, maps)) for normals in channel_normals)
        timings["normal filter"] = time.perf_counter() - t0
    disc = profile_radius(profile) if method == Method.IMAGE_SPACE else 0.0
    return PixelPrepared(buffers, lights, channel_lights, disc)


def pixel_exitance(method: str, profile: SampledProfile, radiant, eta, prep: PixelPrepared, *, samples: int = 32,
                   seed: int = 0, oblique=None, deposit=None):
    """Exitance (H, W, C) of a pixel method: a pure JAX function of the profile and the lights.
    ``oblique`` (a Medium) scales the irradiance by its oblique-incidence law; with ``deposit`` (a
    Medium) point lights are read at its deposit depth."""
    dtype = radiant.dtype
    albedo = profile.albedo().astype(dtype)
    if method == Method.NORMAL_FILTERING:
        law = incidence_law(oblique) if oblique is not None else None  # one H solve for the three channels
        channels = [irradiance([g.astype(dtype) for g in lights], radiant, eta, law=law,
                               deposit=deposit)[..., c] for c, lights in enumerate(prep.channel_lights)]
        return albedo * jnp.stack(channels, -1)
    E = irradiance([g.astype(dtype) for g in prep.lights], radiant, eta, medium=oblique, deposit=deposit)
    if method == Method.LAMBERT:
        return albedo * E
    if method == Method.IMAGE_SPACE:
        return image_space_exitance(profile, E, prep.buffers, samples=samples, disc_radius=prep.disc_radius,
                                    seed=seed)
    raise ValueError(f"unknown pixel method {method!r}; one of lambert, normal filtering, image-space.")


def pixel_radiance(method: str, profile: SampledProfile, radiant, eta, prep: PixelPrepared, *, samples: int = 32,
                   specular: bool = True, roughness: float = 0.35, specular_weight: float = 1.0, seed: int = 0,
                   single_scattering: bool = False, medium=None, oblique=None, deposit=None):
    """Linear radiance (H, W, 3) of a pixel method.

    ``single_scattering`` needs the medium: ``medium`` if given (a profile model other than
    the dipole, sampled through its Gaussians), else the dipole ``profile``'s own."""
    M = pixel_exitance(method, profile, radiant, eta, prep, samples=samples, seed=seed, oblique=oblique,
                       deposit=deposit)
    dtype = M.dtype
    coverage = jnp.asarray(prep.buffers.coverage, dtype)
    cos_view = jnp.asarray((prep.buffers.normal * prep.buffers.view).sum(-1), dtype)
    lights = [g.astype(dtype) for g in prep.lights]
    medium = (profile.medium if medium is None else medium) if single_scattering else None
    L = surface_radiance(M, cos_view, eta, medium=medium, normals=jnp.asarray(prep.buffers.normal, dtype),
                         view_dirs=jnp.asarray(prep.buffers.view, dtype), light_geometry=lights, radiant=radiant,
                         deposit=deposit)
    if specular:
        L = L + specular_radiance(prep.buffers.normal, prep.buffers.view, lights, radiant, eta,
                                  roughness=roughness, weight=specular_weight)
    return L * coverage[..., None]
