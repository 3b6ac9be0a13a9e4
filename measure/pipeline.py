"""The measurement pipeline: images -> calibrated radial profile -> fitted medium.

Pure array code (no file access): :mod:`measure.files` reads the files and calls
:func:`fit_measurement`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import jax.numpy as jnp
import numpy as np

from fitting.medium import MediumFit, fit_medium
from jsss import transport
from jsss.medium import Medium

from .checks import check_measurement, field_diffusion_lengths, field_warnings, fit_quality
from .forward import diffuse_reflectance, observed
from .profile import (Calibrated, RadialProfile, beam_center, beam_sigma, beam_window_mm, calibrate, channel_sums,
                      check_image, radial_profile)

__all__ = ["MeasurementFit", "fit_measurement"]


# At most this many refits with each bin's noise evaluated at the previous fit's expectation
# (RadialProfile.stderr_for).
EXPECTED_NOISE_REFITS = 4


@dataclass(frozen=True)
class MeasurementFit:
    """The fit and what it was fitted to: ``profile.stderr`` holds the errors the fit used (the
    pooled noise model at the fit's expectation, :meth:`measure.profile.RadialProfile.stderr_for`)."""

    fit: MediumFit
    profile: RadialProfile
    calibrated: Calibrated
    center: tuple[float, float]
    beam_sigma_mm: float
    channels: tuple[str, ...]
    model: str = "transport"
    g: float = 0.0
    view_angle_deg: float | None = 0.0
    field_mm: float = np.inf
    r_min_mm: float = 0.0
    pixel_mm: float = np.nan

    @property
    def diffuse_reflectance(self) -> np.ndarray:
        """The fitted medium's total diffuse reflectance R_d per channel (:func:`diffuse_reflectance`)."""
        return np.asarray(diffuse_reflectance(self.fit.medium, model=self.model, g=self.g), float).reshape(-1)

    @property
    def fitted_bins(self) -> np.ndarray:
        """The fitted model's value in each bin of :attr:`profile` ``(B, C)``: the observable the
        fit compared with the bins (radiance factor toward the camera, or exitance), convolved with
        the beam and averaged over the same pixels. Bins inside ``r_min_mm`` were not fitted."""
        return _model_bins(self)

    @property
    def normalized_residuals(self) -> np.ndarray:
        """``(measured - model) / stderr`` per bin and channel ``(B, C)``; NaN for the bins the fit
        left out (inside ``r_min_mm``, or without an error)."""
        prof = self.profile
        fitted = (prof.r_mm >= self.r_min_mm)[:, None] & (prof.stderr > 0)
        safe = np.where(fitted, prof.stderr, 1.0)
        return np.where(fitted, (prof.mean - self.fitted_bins) / safe, np.nan)

    @property
    def field_diffusion_lengths(self) -> np.ndarray:
        """How far the image reaches from the beam (``field_mm``, to the nearest edge) in
        diffusion lengths of each fitted channel (:func:`measure.checks.field_diffusion_lengths`)."""
        return field_diffusion_lengths(self.field_mm, self.fit.medium.sigma_a, self.fit.medium.sigma_s_prime)

    @property
    def warnings(self) -> list[str]:
        """Channels of an ``ok`` fit whose sigma_a is loose because the field is narrow
        (:func:`measure.checks.field_warnings`)."""
        return field_warnings(self.field_diffusion_lengths, self.fit.medium.sigma_a, self.fit.sigma_a_err,
                              self.channels, field_mm=self.field_mm, quality=self.quality)

    @property
    def calibration_sensitivity(self) -> np.ndarray:
        r"""How far sigma_a moves, relatively, per relative error of the calibration (the
        reference's reflectance, the exposure ratio), which the stated errors leave out:
        :math:`|\partial \ln \sigma_a / \partial \ln R_d|` at fixed sigma_s' ``(C,)``
        (:mod:`measure.checks`). Marble's red: 11.7, where refitting with a 1 % brighter reference
        moved sigma_a 9-15 %."""
        medium = self.fit.medium
        sigma_a = jnp.asarray(medium.sigma_a)
        step = 1e-3
        totals = [diffuse_reflectance(Medium(sigma_a * factor, medium.sigma_s_prime, medium.eta), model=self.model,
                                      g=self.g) for factor in (np.exp(-step), np.exp(step))]
        slope = (np.log(np.asarray(totals[1], float)) - np.log(np.asarray(totals[0], float))) / (2 * step)
        with np.errstate(divide="ignore"):
            return np.abs(1.0 / slope).reshape(-1)

    @property
    def failures(self) -> list[str]:
        """Why the fit is not a result, one reason per failing channel (empty for a result): a
        non-finite estimate or error; an error of exactly 0, where the search ended at the edge
        of its range and the data do not constrain the parameter (``--pixel-mm 1e30`` had
        printed sigma_a 1.0955 +- 0); a total diffuse reflectance above 1, which no material
        returns (a measurement scaled x1000 had printed R_d 1.017)."""
        f = self.fit
        values = {"sigma_a": f.medium.sigma_a, "sigma_s_prime": f.medium.sigma_s_prime}
        errors = {"sigma_a": f.sigma_a_err, "sigma_s_prime": f.sigma_s_prime_err}
        total = np.asarray(f.total_reflectance, float).reshape(-1)
        reasons = []
        for c, channel in enumerate(self.channels):
            for name in values:
                value = float(np.asarray(values[name], float).reshape(-1)[c])
                error = float(np.asarray(errors[name], float).reshape(-1)[c])
                if not (np.isfinite(value) and np.isfinite(error)):
                    reasons.append(f"channel {channel}: {name} {value:.4g} +- {error:.2g} is not finite")
                    break
                if error <= 0:
                    reasons.append(f"channel {channel}: {name} {value:.4g} +- 0: the fit ended at the edge of its "
                                   "range, where the data do not constrain it")
                    break
            else:
                if not total[c] <= 1:
                    reasons.append(f"channel {channel}: total diffuse reflectance {total[c]:.4g} > 1, which no "
                                   "material returns")
        return reasons

    @property
    def quality(self) -> list[str]:
        """Per channel ``"ok"`` or ``"poor: ..."`` (:func:`measure.checks.fit_quality`) from chi^2/dof
        with the transport tables' own noise counted (:attr:`fitting.medium.MediumFit.chi2_reduced_tables`):
        an image less noisy than the tables shows their noise as a misfit no parameter removes."""
        return fit_quality(self._judged_chi2)

    @property
    def _judged_chi2(self):
        f = self.fit
        return f.chi2_reduced if f.chi2_reduced_tables is None else f.chi2_reduced_tables

    def table(self) -> dict:
        """Per-channel results as plain lists (the JSON and CSV schema)."""
        f = self.fit
        as_list = lambda x: np.asarray(x, dtype=float).reshape(-1).tolist()  # noqa: E731
        return {
            "channels": list(self.channels),
            "sigma_a": as_list(f.medium.sigma_a),
            "sigma_s_prime": as_list(f.medium.sigma_s_prime),
            "sigma_a_err": as_list(f.sigma_a_err),
            "sigma_s_prime_err": as_list(f.sigma_s_prime_err),
            # The transport tables' own Monte Carlo noise, included in the errors above (in quadrature).
            "sigma_a_table_err": as_list(_or_zeros(f.sigma_a_table_err, f.sigma_a_err)),
            "sigma_s_prime_table_err": as_list(_or_zeros(f.sigma_s_prime_table_err, f.sigma_s_prime_err)),
            "errors_include": ["data noise", "calibration scale"] + (["table noise"] if self.model == "transport"
                                                                     else []),
            "eta": as_list(np.broadcast_to(np.asarray(f.medium.eta), np.shape(f.medium.sigma_a))),
            "total_reflectance": as_list(self.diffuse_reflectance),
            "observable_total": as_list(f.total_reflectance),
            "total_reflectance_in_image": as_list(self.calibrated.total_reflectance),
            "sigma_a_per_calibration": as_list(self.calibration_sensitivity),
            "pixel_mm": float(self.pixel_mm),
            "mean_free_path_mm": as_list(1.0 / (np.asarray(f.medium.sigma_a) + np.asarray(f.medium.sigma_s_prime))),
            "rel_residual": as_list(f.rel_residual),
            "converged": [bool(x) for x in np.asarray(f.converged).reshape(-1)],
            "chi2_reduced": as_list(f.chi2_reduced),
            # The same with the tables' noise in the residuals' covariance: what quality and status judge.
            "chi2_reduced_tables": as_list(self._judged_chi2),
            "quality": self.quality,
            "field_mm": float(self.field_mm),
            "field_diffusion_lengths": as_list(self.field_diffusion_lengths),
            "model": self.model,
            "g": self.g,
            "observable": "exitance" if self.view_angle_deg is None else "radiance",
            "view_angle_deg": self.view_angle_deg,
        }


def _or_zeros(share, like):
    """A fit's error share, or zeros shaped as ``like`` where the fit has none (the dipole)."""
    return np.zeros(np.shape(like)) if share is None else share


def _sum_variance(images, center, pixel_mm):
    """Variance of the sum of each image (a list of ``(H, W, C)``, one centre), from the
    per-pixel scatter in thin annuli.

    Shot noise grows with the signal, so a border estimate of the read noise alone would
    understate the error of the total; the annular scatter (about a straight line in r)
    measures both, wherever the light is. The images are binned together as one image of
    their stacked channels (each channel keeps its own noise model), sharing the rings.
    """
    stacked = np.concatenate(images, axis=-1)
    profile = radial_profile(stacked, center, pixel_mm, n_bins=96, r_min_mm=pixel_mm / 2,
                             r_max_mm=np.hypot(*stacked.shape[:2]) * pixel_mm)
    per_pixel = profile.stderr**2 * profile.count[:, None]
    variance = np.sum(per_pixel * profile.count[:, None], axis=0)
    return np.split(variance, np.cumsum([image.shape[-1] for image in images])[:-1])


def fit_measurement(measurement, reference, pixel_mm: float, eta, *, dark=None, reference_reflectance: float = 0.99,
                    model: str = "transport", g: float = 0.0, view_angle_deg: float | None = 0.0,
                    channels=("R", "G", "B"), n_bins: int = 48, r_min_mm: float | None = None,
                    grid=None, fit_options: dict | None = None) -> MeasurementFit:
    """Calibrate, bin and fit one measurement (images ``(H, W, C)``).

    The beam centre and width come from the reference. The fit models the beam, and bins
    start at ``r_min_mm`` (default: the larger of 2 pixels and 2 beam widths), where the
    image is dominated by the sample rather than by the beam's core. For a slanted camera
    the default starts past the beam's single scattering, a streak one beam wide along the
    camera's azimuth that a ring of pixels hits or misses (three of its decay lengths, from a
    first fit; skin1 at 40 degrees: 2 -> 9 pixels, sigma_s' -3.2 to -4.5 % at chi^2/dof
    10-14 before, within 1.9 % at chi^2/dof 0.1-0.7 after). ``grid`` is the
    Hankel grid of the model (build one with :func:`jsss.layers.hankel.hankel_grid` and pass it
    when fitting many measurements). ``model`` and ``g`` choose the profile model (see
    :func:`fitting.medium.fit_medium`): ``"transport"`` (the default, as ``fit-params``: the scaled
    Monte Carlo tables, exact to radiative transfer, eta 1.0-1.6, g in {0, 0.5, 0.8, 0.9}) or
    ``"dipole"`` (diffusion: tens of percent off near the beam and at low albedo; on the demo's
    marble its sigma_a came out 32-93 % low with chi2/dof 3e4); ``fit_options`` passes its solver options (``init``,
    ``n_starts``, ``max_steps``, ``rtol``, ``atol``).

    The image contract (docs/guides/image_contract.md): a pixel is proportional to the radiance toward the camera,
    which looks at the sample ``view_angle_deg`` from its normal (default 0, straight down;
    the image mapped to the sample plane so that ``pixel_mm`` holds); the beam arrives along
    the normal and loses its Fresnel reflection at entry; the reference is a Lambertian white.
    ``view_angle_deg=None`` reads the pixels as exitance instead (a simulation's tally).

    Raises
    ------
    measure.checks.MeasurementError
        Images that cannot be a measurement: no signal above the noise, a reference that
        is not a beam, a sample narrower than its beam (:func:`measure.checks.check_measurement`).
    """
    calibrated = calibrate(measurement, reference, pixel_mm, reference_reflectance=reference_reflectance, dark=dark)
    offset = 0 if dark is None else np.asarray(dark, dtype=float)
    meas = check_image(measurement, name="measurement") - offset
    ref = check_image(reference, name="reference") - offset
    center = beam_center(ref)
    window = beam_window_mm(ref, pixel_mm)
    sigma = beam_sigma(ref, center, pixel_mm, radius_mm=window)
    meas_var, ref_var = _sum_variance([meas, ref], center, pixel_mm)
    meas_sum = channel_sums(meas)
    check_measurement(meas, ref, center=center, pixel_mm=pixel_mm, window_mm=window, beam_sigma_mm=sigma,
                      signal=meas_sum, signal_stderr=np.sqrt(meas_var), channels=channels)
    # The measurement's own noise enters the total; the reference's sum scales the profile
    # and the total alike, so its error is passed separately as a shared scale error.
    meas_relative_var = meas_var / meas_sum**2
    scale_stderr = np.sqrt(ref_var) / channel_sums(ref)
    total_stderr = np.abs(calibrated.total_reflectance) * np.sqrt(meas_relative_var)

    def fit_beyond(r_min, profile=None, expected=None):
        # ``expected``: bins (B, C) at which the noise model is evaluated instead of the measured means.
        if profile is None:
            profile = radial_profile(calibrated.reflectance, center, pixel_mm, n_bins=n_bins, r_min_mm=r_min)
        stderr = profile.stderr_for(_one_hit_floor(profile) if expected is None else expected)
        # Only bins outside r_min enter the fit: the first (inner disc) bin is dropped.
        outer = profile.r_mm >= r_min
        keep_pixels = outer[profile.bin_index]
        remap = np.cumsum(outer) - 1
        # Pad to shapes fixed by the image size and n_bins, so that every measurement of a
        # batch reuses one compiled fit: padded bins have zero error (ignored), padded pixels
        # go to an extra bin that is dropped.
        n_fit = int(outer.sum())
        mean = np.zeros((n_bins, profile.mean.shape[1]))
        err = np.zeros_like(mean)
        mean[:n_fit], err[:n_fit] = profile.mean[outer], stderr[outer]
        radii = np.zeros(field.size)
        index = np.full(field.size, n_bins)
        used = int(keep_pixels.sum())
        radii[:used] = profile.pixel_r_mm[keep_pixels]
        index[:used] = remap[profile.bin_index[keep_pixels]]
        fit = fit_medium(mean, err, eta, pixel_radii=radii, bin_index=index,
                         total_reflectance=calibrated.total_reflectance, total_stderr=total_stderr,
                         field_radii=field, pixel_area=pixel_mm**2, scale_stderr=scale_stderr, beam_sigma=sigma,
                         model=model, g=g, view_cos=None if view_angle_deg is None else np.cos(np.radians(view_angle_deg)),
                         grid=grid, **(fit_options or {}))
        return replace(profile, stderr=stderr), fit  # the errors the fit used

    rows, cols = np.indices(calibrated.reflectance.shape[:2])
    field = np.hypot(rows - center[0], cols - center[1]).ravel() * pixel_mm
    r_min = r_min_mm or max(2 * pixel_mm, 2 * sigma)
    field_mm = _field_mm(calibrated.reflectance.shape, center, pixel_mm)
    profile, fit = fit_beyond(r_min)
    if r_min_mm is None and view_angle_deg:
        # A slanted camera sees the beam's single scattering as a streak along its azimuth,
        # one beam wide, that a ring of pixels hits or misses: the ring's mean is not the
        # azimuthal average the model is. The bins start past the streak (three decay lengths
        # of the slowest converged channel's, from the first fit's medium; per channel, the
        # faster channels' bins at skin1's blue read chi^2/dof 5 where the common start gave
        # 0.7) and the fit is made again.
        lengths = _streak_length_mm(fit.medium, view_angle_deg, g)[np.asarray(fit.converged, bool).reshape(-1)]
        streak = min(3 * float(np.max(lengths, initial=0.0)), 0.5 * field_mm)
        if streak > r_min:
            r_min = streak
            profile, fit = fit_beyond(r_min)
    for _ in range(EXPECTED_NOISE_REFITS):
        # Then each bin's noise from the fit's expectation there rather than from its own
        # (floored) mean: Pearson's chi-square, not Neyman's (RadialProfile.stderr_for), until no
        # converged channel moves by a tenth of its error (one refit on most images). On the 24
        # channels of benchmarks/camera_angles.py this moved ketchup's green at 40 degrees from
        # +3.9 to +1.8 % and every other estimate by less than one stated error.
        expected = _expected_bins(profile, fit, r_min, model, g)
        previous = fit
        profile, fit = fit_beyond(r_min, profile, expected)
        if _settled(previous, fit):
            break
    return MeasurementFit(fit, profile, calibrated, center, sigma, tuple(channels), model, float(g), view_angle_deg,
                          field_mm, float(r_min), float(pixel_mm))


def _settled(before: MediumFit, after: MediumFit) -> bool:
    """Whether every channel ``after`` calls converged moved from ``before`` by under a tenth of its
    stated error in both coefficients."""
    converged = np.asarray(after.converged, bool).reshape(-1)
    small = converged.copy()
    for key, error in (("sigma_a", after.sigma_a_err), ("sigma_s_prime", after.sigma_s_prime_err)):
        moved = np.abs(np.asarray(getattr(after.medium, key), float) - np.asarray(getattr(before.medium, key), float))
        with np.errstate(invalid="ignore", divide="ignore"):
            small &= (moved.reshape(-1) / np.asarray(error, float).reshape(-1)) < 0.1
    return bool(np.all(~converged | small))


def _field_mm(shape, center, pixel_mm) -> float:
    """The image's half-field around the beam: the distance to its nearest edge [mm]."""
    height, width = shape[:2]
    return float(pixel_mm * (min(center[0], center[1], height - 1 - center[0], width - 1 - center[1]) + 0.5))


def _streak_length_mm(medium, view_angle_deg: float, g: float) -> np.ndarray:
    r"""How fast the beam's single scattering fades along a slanted camera's azimuth [mm], per
    channel.

    Light scattered once at depth :math:`z` on the beam reaches a camera at :math:`\theta` from
    the normal (:math:`\theta_t` inside, :math:`\sin\theta_t = \sin\theta/\eta`) along a path
    :math:`z/\cos\theta_t` and leaves :math:`x = z\tan\theta_t` from the beam, so it fades as
    :math:`e^{-\sigma_t z (1 + 1/\cos\theta_t)} = e^{-x/\ell}` with
    :math:`\ell = \tan\theta_t / (\sigma_t (1 + 1/\cos\theta_t))`, :math:`\sigma_t = \sigma_a
    + \sigma_s'/(1 - g)`. 0 toward the normal."""
    eta = np.asarray(medium.eta, dtype=float)
    sin_t = np.sin(np.radians(view_angle_deg)) / eta
    cos_t = np.sqrt(1 - sin_t**2)
    sigma_t = np.asarray(medium.sigma_a, dtype=float) + np.asarray(medium.sigma_s_prime, dtype=float) / (1 - g)
    with np.errstate(divide="ignore", invalid="ignore"):
        length = np.nan_to_num(sin_t / cos_t / (sigma_t * (1 + 1 / cos_t)), nan=0.0, posinf=0.0)
    return np.broadcast_to(length, np.shape(medium.sigma_a)).reshape(-1)


def _model_bins(result: MeasurementFit) -> np.ndarray:
    """The fitted observable, beam-convolved, averaged over each bin's pixels (``(B, C)``)."""
    prof = result.profile
    at_pixels = observed(result.fit.medium, prof.pixel_r_mm, result.beam_sigma_mm, model=result.model, g=result.g,
                         view_angle_deg=result.view_angle_deg)
    n_bins = prof.r_mm.size
    sums = np.stack([np.bincount(prof.bin_index, at_pixels[:, c], minlength=n_bins)[:n_bins]
                     for c in range(at_pixels.shape[1])], axis=-1)
    counts = np.bincount(prof.bin_index, minlength=n_bins)[:n_bins]
    return sums / np.maximum(counts, 1)[:, None]


def _one_hit_floor(prof: RadialProfile) -> np.ndarray:
    """The measured means, each raised to at least one hit's worth of its bin, for the first fit's
    noise: the shot term ``b`` of the per-pixel variance ``a + b * signal`` is the value one hit
    adds to a pixel (a photon's weight in a walk, a photo-electron in a camera), so a bin of
    ``n`` pixels cannot tell a mean below ``b / n`` from none. Without it the far bins of a walk
    image that no photon reached (means of 1e-48, errors of 1e-27) outweighed the rest: skin1's
    blue at g 0.9 seen at 40 degrees ran to a profile of zero (sigma_s' 1e22 / mm) or came out
    35-100 % high on six of six walks, within 2.5 % with it (the modified Neyman chi-square's
    ``max(N, 1)``)."""
    if prof.noise_model is None:
        return prof.mean
    return np.maximum(prof.mean, prof.noise_model[:, 1] / prof.count[:, None])


def _expected_bins(prof: RadialProfile, fit: MediumFit, r_min: float, model: str, g: float) -> np.ndarray:
    """The fit's model in each bin it fitted (:attr:`MediumFit.model_bins`) where it can stand for
    the bins' expectation; elsewhere the floored measured means (:func:`_one_hit_floor`): in the
    bins inside ``r_min``, and in channels whose estimate the model does not cover (it ran off:
    not finite, or past the transport tables' absorption) or whose model is not finite."""
    medium = fit.medium
    sigma_a = np.asarray(medium.sigma_a, float).reshape(-1)
    sigma_s_prime = np.asarray(medium.sigma_s_prime, float).reshape(-1)
    eta = np.broadcast_to(np.asarray(medium.eta, float).reshape(-1), sigma_a.shape)
    covered = np.isfinite(sigma_a) & np.isfinite(sigma_s_prime) & (sigma_a >= 0) & (sigma_s_prime > 0)
    for c in np.flatnonzero(covered):
        if model == "transport":
            try:
                transport.check_medium(Medium(sigma_a[c], sigma_s_prime[c], eta[c]), g=g)
            except ValueError:
                covered[c] = False
    expected = np.array(_one_hit_floor(prof), dtype=float)  # a copy: written below
    outer = prof.r_mm >= r_min  # the bins fit_medium was given, in order (fit_measurement's fit_beyond)
    binned = np.asarray(fit.model_bins, float)[:int(outer.sum())]
    use = covered & np.all(np.isfinite(binned), axis=0)
    expected[outer] = np.where(use, binned, expected[outer])
    return expected
