r"""What cannot be a measurement, refused before a fit; what a fit's residual says about it.

A least-squares fit returns numbers for any input, so the inputs are checked against what
every beam-profile measurement satisfies (Jensen et al. 2001 sec. 3):

- **The reference is a beam.** A beam on a white diffuser is compact: a Gaussian holds
  :math:`1 - e^{-(3 \cdot 1.18)^2/2} = 0.998` of its light within three half-maximum radii
  of its peak (0.996 sampled on pixels; a top hat all of it). A translucent sample's profile
  has a long tail: images of 256 pixels of 0.05 mm of the Jensen 2001 materials hold
  0.35-0.81 there, of 128 pixels 0.45-0.76, except where the profile is wider than the
  field (chicken, potato on 128 pixels: 0.95-1.0), which no image-based check can tell from
  a wide beam. A reference below :data:`BEAM_MIN_FRACTION` is refused as an image of the
  sample (files swapped, or a measurement passed as a reference). A beam with strong rings
  (an Airy pattern holds about 0.85) is refused too: such a beam is not the Gaussian the
  fit models.
- **The sample widens the beam.** The measured image is the beam convolved with the
  sample's profile, so its second moment about the beam centre is at least the beam's
  (variances add). A "sample" narrower than :data:`MIN_WIDTH_RATIO` times the beam is
  not one.
- **There is a signal.** The measurement's sum (after dark subtraction) must exceed
  :data:`MIN_SIGNAL_TO_NOISE` times its standard error in every channel.

After the fit, :math:`\chi^2` per degree of freedom of the whitened residuals is about 1
when the model and the noise model describe the data. Fits of synthetic images with the
right model give 0.6-2.4 (the pooled read + shot noise model is approximate); a wrong eta
(1.3 for marble's 1.5) gives :math:`10^3-10^4`. Above :data:`POOR_FIT_CHI2` the fit is
marked ``poor`` and the likely causes are named. Above :data:`NOT_A_RESULT_CHI2` (residuals ten
times the noise) the estimate is not a measurement, and the commands keep it out of the
result's place (``fit-params``: ``status: poor``, exit 1 unless ``--accept-poor``). Between the
two the estimate may still be right: raw brackets merged with an approximate noise model fit
marble within 5 % at chi^2/dof 7-9, while the dipole on a transport image (176) is +142 % off in
sigma_a, and a wrong eta (10^3) or ketchup's single-scattering red (6260) further still.

**The field must reach the diffusion length.** sigma_a shows in the profile's decay, which
happens at the diffusion length :math:`1/\sigma_{tr} = 1/\sqrt{3\sigma_a\sigma_t'}`: 18
transport lengths at albedo' 0.999. An image that ends within that reach holds sigma_a only
through the total light, and its stated error says so: walk images of albedo' 0.999 (3e5
photons) gave a stated sigma_a error of 95 % with a half-field of 0.18 diffusion lengths,
5 % at 2.1 and 3.6 % at 4.2 (``benchmarks/measurement_transport.py``). Where the stated error
exceeds :data:`LOOSE_SIGMA_A` and the field is shorter than :data:`MIN_FIELD_DIFFUSION_LENGTHS`,
:func:`field_warnings` names the field as the cause and the fix (larger pixels or a larger
image), not the fit.

**The calibration is not in the stated errors.** The fit weighs the image's total (per unit
of the reference's) as one residual beside the profile, and at high albedo sigma_a follows the
total steeply: for marble a 1 % error in the reference's reflectance or in the exposure ratio
moves sigma_a by 7-15 %, measured by refitting the same synthetic image at 0.75 diffusion
lengths and 6-9 % at 2-4 (``tests/measure/test_recovery.py``). A wider field does not remove
this; it only raises chi^2/dof (3-5) where the decay disagrees with the total. The commands print
the sensitivity :math:`|\partial \ln\sigma_a / \partial \ln R_d|`
(:attr:`measure.pipeline.MeasurementFit.calibration_sensitivity`) beside every fit.

**Scale is not in the profile.** Every coefficient scales as 1/pixel size: an image with
``--pixel-mm`` ten times too large fits exactly as well, with sigma_a and sigma_s' ten times too
small. No residual can show it, so the pixel size must be measured (:mod:`measure.target`).
"""

from __future__ import annotations

import numpy as np

from fitting.statistics import POOR_FIT_CHI2

from .profile import beam_sigma, half_max_radius_px

__all__ = [
    "BEAM_MIN_FRACTION",
    "MIN_SIGNAL_TO_NOISE",
    "MIN_WIDTH_RATIO",
    "POOR_FIT_CHI2",
    "NOT_A_RESULT_CHI2",
    "LOOSE_SIGMA_A",
    "MIN_FIELD_DIFFUSION_LENGTHS",
    "MeasurementError",
    "check_measurement",
    "field_diffusion_lengths",
    "field_warnings",
    "fit_quality",
]

BEAM_MIN_FRACTION = 0.9
MIN_WIDTH_RATIO = 0.8
MIN_SIGNAL_TO_NOISE = 5.0
NOT_A_RESULT_CHI2 = 100.0
MIN_FIELD_DIFFUSION_LENGTHS = 2.0
LOOSE_SIGMA_A = 0.1


class MeasurementError(ValueError):
    """Images that cannot be a beam-profile measurement; the message says why and what to check."""


def _light_within(image, center, radius_px):
    """Fraction of the (channel-summed, non-negative) light within ``radius_px`` of ``center``."""
    total = np.clip(image.sum(axis=-1), 0, None)
    rows, cols = np.indices(total.shape)
    inside = np.hypot(rows - center[0], cols - center[1]) <= radius_px
    return float(total[inside].sum() / total.sum())


def check_measurement(measurement, reference, *, center, pixel_mm: float, window_mm: float, beam_sigma_mm: float,
                      signal, signal_stderr, channels) -> None:
    """Raise :class:`MeasurementError` for images that cannot be a measurement (module docstring).

    Parameters
    ----------
    measurement, reference : ndarray ``(H, W, C)``
        Dark-subtracted images.
    center : (float, float)
        Beam centre (row, col) from the reference.
    pixel_mm, window_mm : float
        Pixel size and the radius [mm] within which widths are measured
        (:func:`measure.profile.beam_window_mm`).
    beam_sigma_mm : float
        RMS width per axis of the reference about ``center`` within ``window_mm``.
    signal, signal_stderr : ndarray ``(C,)``
        Sum of the measurement per channel and its standard error.
    channels : sequence of str
        Channel names, for the messages.
    """
    if measurement.shape == reference.shape and np.array_equal(measurement, reference):
        raise MeasurementError("the measurement and the reference are the same image; the reference is the beam on "
                               "a white diffuser, the measurement the beam on the sample")
    radius = max(3 * half_max_radius_px(reference), 3.0)
    fraction = _light_within(reference, center, radius)
    if fraction < BEAM_MIN_FRACTION:
        raise MeasurementError(
            f"the reference is not a beam: it holds {fraction:.0%} of its light within 3 half-maximum radii "
            f"({radius:.1f} px) of its peak, where a beam holds over {BEAM_MIN_FRACTION:.0%}; is it an image of the "
            "sample (measurement and reference swapped?)")
    for name, total, error in zip(channels, np.asarray(signal, float), np.asarray(signal_stderr, float)):
        if not total > MIN_SIGNAL_TO_NOISE * error or total <= 0:
            snr = total / error if error > 0 else 0.0
            raise MeasurementError(
                f"the measurement has no signal above the noise in channel {name} (sum {total:.3g}, "
                f"signal-to-noise {snr:.2g}, needs > {MIN_SIGNAL_TO_NOISE:g}); is the beam on, the exposure long "
                "enough, the dark frame the right one?")
    measurement_sigma_mm = beam_sigma(measurement, center, pixel_mm, radius_mm=window_mm)
    if measurement_sigma_mm < MIN_WIDTH_RATIO * beam_sigma_mm:
        raise MeasurementError(
            f"the measurement is narrower than its reference beam (RMS width {measurement_sigma_mm:.3g} mm against "
            f"the beam's {beam_sigma_mm:.3g} mm); a sample can only widen the beam: measurement and reference "
            "swapped, or taken with different beams?")


def fit_quality(chi2_reduced) -> list[str]:
    """Per channel: ``"ok"``, or ``"poor: ..."`` naming chi^2/dof and the likely causes."""
    out = []
    for value in np.asarray(chi2_reduced, float).reshape(-1):
        if np.isfinite(value) and value <= POOR_FIT_CHI2:
            out.append("ok")
        else:
            out.append(f"poor: chi2/dof {value:.3g} (expected about 1); likely a wrong eta, a wrong model "
                       "(the dipole is biased near the source) or a reference taken at another exposure")
    return out


def field_diffusion_lengths(field_mm: float, sigma_a, sigma_s_prime):
    r"""Half-width of the field [mm] over the diffusion length of each fitted channel:
    :math:`r_{field} \sqrt{3 \sigma_a (\sigma_a + \sigma_s')}` (``(C,)``)."""
    sigma_a = np.clip(np.asarray(sigma_a, float).reshape(-1), 0.0, None)
    sigma_t = sigma_a + np.asarray(sigma_s_prime, float).reshape(-1)
    return float(field_mm) * np.sqrt(3 * sigma_a * sigma_t)


def field_warnings(lengths, sigma_a, sigma_a_err, channels, *, field_mm: float, quality=None) -> list[str]:
    """One message per channel whose sigma_a is loose because the image ends before the
    profile's decay (module docstring); empty where the field is wide enough or the error small.
    Channels whose ``quality`` (:func:`fit_quality`) is not ``"ok"`` are skipped: a poor fit's
    errors mean nothing, and its own warning names the likelier causes."""
    quality = ["ok"] * len(channels) if quality is None else quality
    out = []
    for name, reach, value, error, fit in zip(channels, np.asarray(lengths, float).reshape(-1),
                                              np.asarray(sigma_a, float).reshape(-1),
                                              np.asarray(sigma_a_err, float).reshape(-1), quality):
        relative = error / value if value > 0 else np.inf
        if fit == "ok" and reach < MIN_FIELD_DIFFUSION_LENGTHS and not relative <= LOOSE_SIGMA_A:
            diffusion_mm = field_mm / reach if reach > 0 else np.inf
            out.append(f"channel {name}: sigma_a is loosely constrained (stated error {relative:.0%}): the image "
                       f"reaches {field_mm:.3g} mm from the beam, {reach:.2g} diffusion lengths (1/sigma_tr = "
                       f"{diffusion_mm:.3g} mm), and sigma_a shows in the decay beyond; widen the field to "
                       f"{MIN_FIELD_DIFFUSION_LENGTHS:g}+ diffusion lengths (larger pixels or a larger image)")
    return out

