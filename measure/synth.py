r"""Synthetic beam-profile measurements with a known answer.

The sample's exitance is the dipole (or transport) profile convolved with a Gaussian beam of
standard deviation ``beam_sigma_mm`` (computed in frequency space: the dipole's closed-form
spectrum or the tables' forward Hankel transform, times :math:`e^{-k^2\sigma^2/2}`, one
inverse Hankel transform), sampled at pixel centres; the camera looking down records
radiance, the exitance times :math:`\pi (1 - F(0))` times the diffusion exit law
(``view_angle_deg``). The reference is the beam on a white Lambertian diffuser of
reflectance ``reference_reflectance``. Images whose truth is radiative transfer come from
:mod:`measure.synth_transport` (a walk). The camera is linear: an image value :math:`v`
exposed for ``t`` collects :math:`v\,t\,n_{ph}` photo-electrons (Poisson), plus Gaussian
read noise and a dark offset, clipped at ``saturation``. ``exposures`` gives brackets; without them one
(already HDR) frame of ``t = 1`` is returned.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jsss.medium import Medium

from .exr import write_exr
from .forward import diffuse_reflectance, observed

__all__ = ["SyntheticMeasurement", "synthesize", "write_measurement"]


@dataclass
class SyntheticMeasurement:
    """Images ``(H, W, C)`` and the truth. ``frames`` holds ``(image, exposure)`` brackets."""

    measurement: np.ndarray
    reference: np.ndarray
    dark: np.ndarray | None
    frames: list = field(default_factory=list)
    reference_frames: list = field(default_factory=list)
    truth: dict = field(default_factory=dict)


def _beam(radii_mm, beam_sigma_mm, channels):
    g = np.exp(-(radii_mm**2) / (2 * beam_sigma_mm**2)) / (2 * np.pi * beam_sigma_mm**2)
    return np.repeat(g[..., None], channels, axis=-1)


def synthesize(medium: Medium, *, pixel_mm: float = 0.05, size: int = 256, beam_sigma_mm: float = 0.05,
               power: float = 1.0, gain: float = 1.0, photons_per_unit: float = 1e7, read_noise: float = 2.0,
               dark_level: float = 0.0, exposures=None, saturation: float | None = None,
               reference_reflectance: float = 0.99, center_offset=(0.3, -0.2), noise: bool = True,
               view_angle_deg: float | None = 0.0, model: str = "transport", g: float = 0.0, seed: int = 0,
               grid=None) -> SyntheticMeasurement:
    """Simulate a measurement of ``medium`` (RGB or one channel) and its white reference.

    Parameters
    ----------
    medium : Medium
    pixel_mm : float, keyword-only
        Pixel pitch on the sample [mm].
    size : int, keyword-only
        Image is ``size x size``.
    beam_sigma_mm : float, keyword-only
        Gaussian beam standard deviation [mm].
    power, gain : float, keyword-only
        Incident power and camera gain; an image value is ``gain * power * R``.
    photons_per_unit : float, keyword-only
        Photo-electrons per unit image value per unit exposure (sets the shot noise).
    read_noise : float, keyword-only
        Gaussian read noise [electrons].
    dark_level : float, keyword-only
        Offset in image units added to every frame; a matching dark frame is returned.
    exposures : sequence of float, optional, keyword-only
        Exposure times of brackets, returned in ``frames`` and ``reference_frames`` (each
        clipped at ``saturation``) for the caller to merge; ``measurement`` and
        ``reference`` stay single unclipped HDR frames of exposure 1.
    saturation : float, optional, keyword-only
        Clip level of a bracket in image units (default: none).
    center_offset : (float, float), keyword-only
        Sub-pixel offset (rows, cols) of the beam from the image centre.
    noise : bool, keyword-only
        False gives the exact expected images.
    view_angle_deg : float or None, keyword-only
        The camera's angle from the normal (default 0): pixels record the radiance toward it
        under the diffusion exit law, per unit incident flux (the beam loses F(0) at entry),
        the image contract of :func:`measure.pipeline.fit_measurement`. None gives exitance
        images (the contract before 2026-11-25).
    model : {"dipole", "transport"}, keyword-only
        The profile the images are made with: the transport tables (the default, as the fit's;
        their radiance; Henyey-Greenstein ``g``), or the dipole (diffusion exit law for radiance). Either way the
        images agree with the model of the same name in the fit by construction: for a
        truth outside the models use :mod:`measure.synth_transport`.
    g : float, keyword-only
    seed : int, keyword-only
    grid : HankelGrid, optional, keyword-only
        Transform grid for the beam convolution (default :func:`jsss.layers.hankel.hankel_grid`).
    """
    rng = np.random.default_rng(seed)
    centre = ((size - 1) / 2 + center_offset[0], (size - 1) / 2 + center_offset[1])
    rows, cols = np.indices((size, size))
    radii = np.hypot(rows - centre[0], cols - centre[1]) * pixel_mm
    scale = gain * power
    sample = scale * observed(medium, radii, beam_sigma_mm, grid, model=model, g=g, view_angle_deg=view_angle_deg)
    channels = sample.shape[-1]
    reference = scale * reference_reflectance * _beam(radii, beam_sigma_mm, channels)

    def expose(value, t, clip=True):
        if not noise:
            frame = value * t
        else:
            electrons = rng.poisson(np.clip(value * t * photons_per_unit, 0, None)).astype(float)
            electrons += rng.normal(0.0, read_noise, value.shape)
            frame = electrons / photons_per_unit
        frame = frame + dark_level
        return frame if (saturation is None or not clip) else np.minimum(frame, saturation)

    def dark_frame():
        if not noise:
            return np.full_like(sample, dark_level)
        return dark_level + rng.normal(0.0, read_noise, sample.shape) / photons_per_unit

    truth = dict(sigma_a=np.asarray(medium.sigma_a).tolist(), sigma_s_prime=np.asarray(medium.sigma_s_prime).tolist(),
                 eta=np.asarray(medium.eta).tolist(),
                 total_reflectance=np.asarray(diffuse_reflectance(medium, model=model, g=float(g))).tolist(),
                 pixel_mm=pixel_mm, size=size, beam_sigma_mm=beam_sigma_mm, center=list(centre),
                 reference_reflectance=reference_reflectance, photons_per_unit=photons_per_unit, read_noise=read_noise,
                 dark_level=dark_level, exposures=None if exposures is None else list(exposures), saturation=saturation,
                 seed=seed, noise=noise, view_angle_deg=view_angle_deg, model=model, g=g)
    dark = dark_frame() if (dark_level or noise) else None
    measurement, ref_image = expose(sample, 1.0, clip=False), expose(reference, 1.0, clip=False)
    if exposures is None:
        return SyntheticMeasurement(measurement, ref_image, dark, truth=truth)
    frames = [(expose(sample, t), float(t)) for t in exposures]
    reference_frames = [(expose(reference, t), float(t)) for t in exposures]
    return SyntheticMeasurement(measurement, ref_image, dark, frames, reference_frames, truth)


def write_measurement(directory, synthetic: SyntheticMeasurement, *, name: str = "sample",
                      pixel_type: str = "float") -> dict:
    """Write ``NAME.exr``, ``NAME_ref.exr`` (and ``NAME_dark.exr``) plus ``NAME.json`` with the truth.

    Brackets are written as ``NAME_t{i}.exr`` / ``NAME_ref_t{i}.exr`` with their exposure
    in the header (``jsss_exposure``). Returns the paths written, by role.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    channels = ("R", "G", "B") if synthetic.measurement.shape[-1] == 3 else ("Y",)
    attrs = {"jsss_pixel_mm": float(synthetic.truth["pixel_mm"])}
    paths = {
        "measurement": write_exr(directory / f"{name}.exr", synthetic.measurement, channels, pixel_type=pixel_type, attributes=attrs),
        "reference": write_exr(directory / f"{name}_ref.exr", synthetic.reference, channels, pixel_type=pixel_type, attributes=attrs),
    }
    if synthetic.dark is not None:
        paths["dark"] = write_exr(directory / f"{name}_dark.exr", synthetic.dark, channels, pixel_type=pixel_type, attributes=attrs)
    for i, ((frame, t), (ref, _)) in enumerate(zip(synthetic.frames, synthetic.reference_frames)):
        paths[f"frame_{i}"] = write_exr(directory / f"{name}_t{i}.exr", frame, channels, pixel_type=pixel_type,
                                        attributes={**attrs, "jsss_exposure": t})
        paths[f"reference_frame_{i}"] = write_exr(directory / f"{name}_ref_t{i}.exr", ref, channels,
                                                  pixel_type=pixel_type, attributes={**attrs, "jsss_exposure": t})
    sidecar = directory / f"{name}.json"
    sidecar.write_text(json.dumps({"truth": synthetic.truth, "files": {k: v.name for k, v in paths.items()}}, indent=2))
    paths["sidecar"] = sidecar
    return paths
