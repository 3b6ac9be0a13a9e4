r"""Camera images whose truth is radiative transfer: a random walk per channel, not a model.

The truth for testing a fit must not share the fit's assumptions, so these images come from
photons, not from the transport tables the fit uses. By default the camera looks from exactly
``view_deg`` (0: along the normal), as a real one does: :func:`camera_walk`, a NumPy walk
that shares no code with jsss's walks or tables (absorption in the walk, a photon surviving a
collision with probability :math:`\sigma_s/\sigma_t`; Henyey-Greenstein turns on a frame of
cross products; Fresnel's equations in their angle form), sends from every collision a
next-event estimate toward the camera's direction (see :func:`camera_walk`). Each photon
enters at a point drawn from the Gaussian beam, and its estimates land where their straight
paths to the camera meet the surface. The image is the white-reference calibrated camera
quantity :math:`\pi (1 - F(0)) L` of :func:`measure.pipeline.fit_measurement`'s contract, per
unit entering flux; its noise is the walk's own (no read noise is added).

With ``cone_deg`` the camera instead accepts the photons of a :mod:`jsss.transport.photon_walk`
walk that leave within ``cone_deg`` of the normal: the radiance averaged over
:math:`\cos\theta \in [\cos\theta_c, 1]` weighted by :math:`\cos\theta`,

.. math:: L = \frac{\sum w}{N A\,\pi (1 - \cos^2\theta_c)},

which near the beam differs from the radiance at 0 degrees by tens of percent (the
benchmarks that predate the exact direction use it).
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf

from jsss import transport
from jsss.medium import Medium
from jsss.transport.montecarlo import _params
from jsss.transport.photon_walk import run_walk

from .synth import SyntheticMeasurement

__all__ = ["camera_walk", "leaving_reflectance", "pixel_beam_reference", "synthesize_walk"]


def pixel_beam_reference(size: int, centre, pixel_mm: float, beam_sigma_mm: float, *, channels: int = 1,
                         reflectance: float = 0.99) -> np.ndarray:
    """The white reference as a camera records it: the Gaussian beam's irradiance times
    ``reflectance``, integrated over each pixel (per unit area, ``(size, size, channels)``).

    The walk's photons are counted per pixel, so its image is integrated over pixels too;
    a reference sampled at pixel centres would be narrower than the beam the walk's image
    saw by the pixel's own width (variance ``pixel**2 / 12`` per axis: 8 % of the beam's
    variance for a beam one pixel wide), and the fit would convolve with the wrong beam.
    """
    edges = (np.arange(size + 1) - 0.5) * pixel_mm
    scale = np.sqrt(2.0) * beam_sigma_mm
    rows = np.diff(0.5 * erf((edges - centre[0] * pixel_mm) / scale))
    cols = np.diff(0.5 * erf((edges - centre[1] * pixel_mm) / scale))
    image = reflectance * np.outer(rows, cols) / pixel_mm**2
    return np.repeat(image[..., None], channels, axis=-1)


def leaving_reflectance(cos_inside, eta):
    r"""Unpolarised Fresnel reflectance from inside a medium of relative index ``eta`` to outside,
    in the angle form :math:`\frac12(\sin^2(\theta_i-\theta_t)/\sin^2(\theta_i+\theta_t) +
    \tan^2(\theta_i-\theta_t)/\tan^2(\theta_i+\theta_t))`; 1 past the critical angle."""
    theta_i = np.arccos(np.clip(cos_inside, 0.0, 1.0))
    sin_t = eta * np.sin(theta_i)
    theta_t = np.arcsin(np.minimum(sin_t, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = np.sin(theta_i - theta_t) / np.sin(theta_i + theta_t)
        rp = np.tan(theta_i - theta_t) / np.tan(theta_i + theta_t)
        r = 0.5 * (rs**2 + rp**2)
    r = np.where(theta_i < 1e-6, ((eta - 1) / (eta + 1)) ** 2, r)
    return np.where(sin_t >= 1.0, 1.0, np.nan_to_num(r, nan=1.0))


def _turned(direction, cos_t, phi):
    """Directions (n, 3) turned by polar angle acos(cos_t) and azimuth phi about themselves."""
    helper = np.where(np.abs(direction[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(direction, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(direction, e1)
    sin_t = np.sqrt(np.maximum(1 - cos_t**2, 0.0))
    return cos_t[:, None] * direction + (sin_t * np.cos(phi))[:, None] * e1 + (sin_t * np.sin(phi))[:, None] * e2


def camera_walk(sigma_a, sigma_s_prime, eta, g, view_deg, *, photons, rng, tally, entry_sigma_mm=0.0,
                batch=200_000):
    r"""Walk ``photons`` photons into a half space and send every collision's estimate to ``tally``.

    The medium fills :math:`z < 0`; photons enter at the origin (plus a Gaussian offset of
    ``entry_sigma_mm`` per axis, one per photon) going down. The camera looks from outside at
    ``view_deg`` to the normal, in the x-z plane; inside, its direction :math:`\omega` makes
    :math:`\theta_i` with the normal, :math:`\sin\theta_i = \sin\theta_o/\eta`. The radiance it
    records, integrated over a patch of the surface, is a volume integral over the collisions,
    so each collision at depth :math:`z` adds

    .. math:: c = \frac{\sigma_s}{\sigma_t}\, p(\mathbf u\cdot\omega)\,
                 \frac{e^{-\sigma_t z/\cos\theta_i}}{\cos\theta_i}\, \frac{1 - R(\theta_i)}{\eta^2}

    (``u`` the direction before the collision; :math:`L/n^2` is conserved across the boundary)
    at the point where its straight path along :math:`\omega` meets the surface.
    ``tally(x_mm, y_mm, c)`` receives them per event; the caller divides by ``photons`` and by
    its bins' areas for the radiance per unit entering flux [1/(mm^2 sr)].
    """
    sigma_s = sigma_s_prime / (1 - g)
    sigma_t = sigma_a + sigma_s
    albedo = sigma_s / sigma_t
    sin_i = np.sin(np.radians(view_deg)) / eta
    cos_i = np.sqrt(1 - sin_i**2)
    to_camera = np.array([sin_i, 0.0, cos_i])
    carry = albedo * (1 - leaving_reflectance(cos_i, eta)) / (eta**2 * cos_i)
    for start in range(0, photons, batch):
        n = min(batch, photons - start)
        position = np.zeros((n, 3))
        position[:, :2] = rng.normal(0.0, 1.0, (n, 2)) * entry_sigma_mm
        direction = np.tile([0.0, 0.0, -1.0], (n, 1))
        while position.shape[0]:
            free = rng.exponential(1 / sigma_t, position.shape[0])
            up = direction[:, 2] > 0
            to_surface = np.where(up, -position[:, 2] / np.where(up, direction[:, 2], 1.0), np.inf)
            hit = free >= to_surface
            position += direction * np.minimum(free, to_surface)[:, None]
            reflected = hit & (rng.random(hit.size) < leaving_reflectance(np.abs(direction[:, 2]), eta))
            direction[reflected, 2] *= -1
            position[hit, 2] = 0.0
            collide = ~hit
            where, incoming = position[collide], direction[collide]
            distance = -where[:, 2] / cos_i
            cos_phase = incoming @ to_camera
            phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos_phase) ** 1.5)
            tally(where[:, 0] + distance * to_camera[0], where[:, 1], carry * phase * np.exp(-sigma_t * distance))
            if abs(g) < 1e-9:
                cos_t = rng.uniform(-1.0, 1.0, incoming.shape[0])
            else:
                cos_t = (1 + g * g - ((1 - g * g) / (1 - g + 2 * g * rng.random(incoming.shape[0]))) ** 2) / (2 * g)
            direction[collide] = _turned(incoming, np.clip(cos_t, -1, 1), rng.uniform(0, 2 * np.pi, incoming.shape[0]))
            survives = reflected | (collide & (rng.random(hit.size) < albedo))
            position, direction = position[survives], direction[survives]


def synthesize_walk(medium: Medium, *, g: float = 0.0, photons: int = 1_000_000, pixel_mm: float = 0.05,
                    size: int = 128, beam_sigma_mm: float = 0.05, view_deg: float = 0.0, cone_deg: float | None = None,
                    reference_reflectance: float = 0.99, center_offset=(0.3, -0.2), max_steps: int = 1_000_000,
                    seed: int = 0, progress: bool = False) -> SyntheticMeasurement:
    """Camera and white-reference images of ``medium`` from random walks.

    Parameters
    ----------
    medium : Medium
        One value or one per channel (``sigma_a``, ``sigma_s_prime`` in 1/mm, ``eta``).
    g : float, keyword-only
        Henyey-Greenstein mean cosine; the walk scatters with ``sigma_s = sigma_s' / (1 - g)``.
    photons : int, keyword-only
        Photons per channel entering the sample.
    pixel_mm, size, beam_sigma_mm, center_offset : keyword-only
        As :func:`measure.synth.synthesize`; pixels are on the sample plane.
    view_deg : float, keyword-only
        The camera's exact direction [degrees to the normal], in [0, 90): :func:`camera_walk`.
    cone_deg : float, optional, keyword-only
        Instead, a camera along the normal accepting photons within this half-angle [degrees]
        of a :mod:`jsss.transport.photon_walk` walk (``max_steps`` caps it).
    seed : int, keyword-only
        Channel ``c`` walks with seed ``seed * 16 + c``.

    Returns
    -------
    SyntheticMeasurement
        Without noise other than the walk's, and without a dark frame (``dark`` None).
    """
    eta = np.broadcast_to(np.asarray(medium.eta, float), medium.shape).reshape(-1)
    sigma_a = np.broadcast_to(np.asarray(medium.sigma_a, float), medium.shape).reshape(-1)
    sigma_s_prime = np.broadcast_to(np.asarray(medium.sigma_s_prime, float), medium.shape).reshape(-1)
    if cone_deg is not None and not 0 < cone_deg < 90:
        raise ValueError(f"synthesize_walk(cone_deg=...) must lie in (0, 90) degrees; got {cone_deg}.")
    if not 0 <= view_deg < 90:
        raise ValueError(f"synthesize_walk(view_deg=...) must lie in [0, 90) degrees; got {view_deg}.")
    rng = np.random.default_rng(seed)
    centre = ((size - 1) / 2 + center_offset[0], (size - 1) / 2 + center_offset[1])
    images = []
    for c in range(eta.size):
        counts = np.zeros(size * size)

        def add(x, y, weight, counts=counts):  # x, y [mm] from the beam's centre, on the sample plane
            row, col = centre[0] + x / pixel_mm, centre[1] + y / pixel_mm
            inside = (row >= -0.5) & (row < size - 0.5) & (col >= -0.5) & (col < size - 0.5)
            flat = np.round(row[inside]).astype(int) * size + np.round(col[inside]).astype(int)
            counts[:] += np.bincount(flat, weight[inside], minlength=size * size)

        entering = float(transport.entry_transmittance(eta[c]))
        if cone_deg is None:
            camera_walk(sigma_a[c], sigma_s_prime[c], eta[c], g, view_deg, photons=photons,
                        rng=np.random.default_rng(seed * 16 + c), tally=add, entry_sigma_mm=beam_sigma_mm)
            radiance_factor = entering * np.pi * counts / (photons * pixel_mm**2)  # pi (1 - F0) L
        else:
            one = Medium(sigma_a[c], sigma_s_prime[c], eta[c])
            params = _params([one], [np.inf], g=g, eta_above=1 / eta[c], eta_below=1 / eta[c], relative=True)
            walk = run_walk(params, n_photons=photons, max_steps=max_steps, seed=seed * 16 + c, progress=progress,
                            label=f"synthesize_walk channel {c}")
            cos_cone = np.cos(np.radians(cone_deg))
            seen = (walk.side == 1) & (walk.exit_cos >= cos_cone)
            radius, weight = walk.radius[seen], walk.weight[seen]
            entry = rng.normal(0.0, beam_sigma_mm, (radius.size, 2))
            azimuth = rng.uniform(0.0, 2 * np.pi, radius.size)
            add(entry[:, 0] + radius * np.cos(azimuth), entry[:, 1] + radius * np.sin(azimuth), weight)
            radiance_factor = entering * counts / (photons * pixel_mm**2 * (1 - cos_cone**2))  # pi (1 - F0) L
        images.append(radiance_factor.reshape(size, size))
    sample = np.stack(images, axis=-1)
    reference = pixel_beam_reference(size, centre, pixel_mm, beam_sigma_mm, channels=sample.shape[-1],
                                     reflectance=reference_reflectance)
    truth = dict(sigma_a=sigma_a.tolist(), sigma_s_prime=sigma_s_prime.tolist(), eta=eta.tolist(), g=float(g),
                 pixel_mm=pixel_mm, size=size, beam_sigma_mm=beam_sigma_mm, center=list(centre),
                 reference_reflectance=reference_reflectance, photons=int(photons), cone_deg=cone_deg, seed=seed,
                 view_angle_deg=0.0 if cone_deg is not None else float(view_deg),
                 model="random walk" if cone_deg is not None else "random walk, next-event estimates")
    return SyntheticMeasurement(sample, reference, None, truth=truth)
