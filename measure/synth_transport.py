r"""Camera images whose truth is radiative transfer: a random walk per channel, not a model.

The truth for testing a fit must not share the fit's assumptions, so these images come from
photons, not from the transport tables the fit uses: one walk of :mod:`jsss.transport.photon_walk`
per channel through the half space of the given medium (absorption by weight, the exact
Fresnel boundary, Henyey-Greenstein ``g``), with its own seed. Each photon enters at a
point drawn from the Gaussian beam, and leaves at its recorded radius in a uniformly random
azimuth; those leaving within ``cone_deg`` of the normal are what a camera looking straight
down collects. The radiance estimate of a pixel of area :math:`A` is

.. math:: L = \frac{\sum w}{N A\,\pi (1 - \cos^2\theta_c)},

(per unit entering flux: the projected solid angle of the cone is
:math:`\pi(1 - \cos^2\theta_c)`), and the image is the white-reference calibrated camera
quantity :math:`\pi (1 - F(0)) L` of :func:`measure.pipeline.fit_measurement`'s contract.
Noise is the walk's own (Poisson-like in the photon counts), so it has the shot-noise form
that the pipeline's noise model assumes; no read noise is added.

A cone is a finite acceptance: the estimate is the radiance averaged over
:math:`\cos\theta \in [\cos\theta_c, 1]` weighted by :math:`\cos\theta`, not exactly at 0
degrees. ``benchmarks/measurement.py`` measures what that average differs by.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf

from jsss import transport
from jsss.medium import Medium
from jsss.transport.montecarlo import _params
from jsss.transport.photon_walk import run_walk

from .synth import SyntheticMeasurement

__all__ = ["pixel_beam_reference", "synthesize_walk"]


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


def synthesize_walk(medium: Medium, *, g: float = 0.0, photons: int = 1_000_000, pixel_mm: float = 0.05,
                    size: int = 128, beam_sigma_mm: float = 0.05, cone_deg: float = 10.0,
                    reference_reflectance: float = 0.99, center_offset=(0.3, -0.2), max_steps: int = 1_000_000,
                    seed: int = 0, progress: bool = False) -> SyntheticMeasurement:
    """Camera (0 degrees) and white-reference images of ``medium`` from random walks.

    Parameters
    ----------
    medium : Medium
        One value or one per channel (``sigma_a``, ``sigma_s_prime`` in 1/mm, ``eta``).
    g : float, keyword-only
        Henyey-Greenstein mean cosine; the walk scatters with ``sigma_s = sigma_s' / (1 - g)``.
    photons : int, keyword-only
        Photons per channel entering the sample.
    pixel_mm, size, beam_sigma_mm, center_offset : keyword-only
        As :func:`measure.synth.synthesize`.
    cone_deg : float, keyword-only
        Acceptance half-angle of the camera's direction [degrees].
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
    if not 0 < cone_deg < 90:
        raise ValueError(f"synthesize_walk(cone_deg=...) must lie in (0, 90) degrees; got {cone_deg}.")
    rng = np.random.default_rng(seed)
    centre = ((size - 1) / 2 + center_offset[0], (size - 1) / 2 + center_offset[1])
    cos_cone = np.cos(np.radians(cone_deg))
    images = []
    for c in range(eta.size):
        one = Medium(sigma_a[c], sigma_s_prime[c], eta[c])
        params = _params([one], [np.inf], g=g, eta_above=1 / eta[c], eta_below=1 / eta[c], relative=True)
        walk = run_walk(params, n_photons=photons, max_steps=max_steps, seed=seed * 16 + c, progress=progress,
                        label=f"synthesize_walk channel {c}")
        seen = (walk.side == 1) & (walk.exit_cos >= cos_cone)
        radius, weight = walk.radius[seen], walk.weight[seen]
        entry = rng.normal(0.0, beam_sigma_mm, (radius.size, 2))
        azimuth = rng.uniform(0.0, 2 * np.pi, radius.size)
        row = centre[0] + (entry[:, 0] + radius * np.cos(azimuth)) / pixel_mm
        col = centre[1] + (entry[:, 1] + radius * np.sin(azimuth)) / pixel_mm
        inside = (row >= -0.5) & (row < size - 0.5) & (col >= -0.5) & (col < size - 0.5)
        counts = np.zeros(size * size)
        flat = np.round(row[inside]).astype(int) * size + np.round(col[inside]).astype(int)
        np.add.at(counts, flat, weight[inside])
        entering = float(transport.entry_transmittance(eta[c]))
        radiance_factor = entering * counts / (photons * pixel_mm**2 * (1 - cos_cone**2))  # pi (1 - F0) L
        images.append(radiance_factor.reshape(size, size))
    sample = np.stack(images, axis=-1)
    reference = pixel_beam_reference(size, centre, pixel_mm, beam_sigma_mm, channels=sample.shape[-1],
                                     reflectance=reference_reflectance)
    truth = dict(sigma_a=sigma_a.tolist(), sigma_s_prime=sigma_s_prime.tolist(), eta=eta.tolist(), g=float(g),
                 pixel_mm=pixel_mm, size=size, beam_sigma_mm=beam_sigma_mm, center=list(centre),
                 reference_reflectance=reference_reflectance, photons=int(photons), cone_deg=cone_deg, seed=seed,
                 view_angle_deg=0.0, model="random walk")
    return SyntheticMeasurement(sample, reference, None, truth=truth)
