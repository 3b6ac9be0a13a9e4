r"""From calibrated beam-profile images to radial profiles (Jensen et al. 2001 sec. 3).

The image contract (docs/guides/image_contract.md): a measurement pixel is :math:`p_i = K\Phi R_d(r_i)`; the
reference (a white diffuse reflector of total reflectance :math:`\rho_{ref}`, same beam and
camera) sums to :math:`K\Phi\rho_{ref}/A` with :math:`A` the area of one pixel, so

.. math:: R_d(r_i) = \frac{\rho_{ref}\,p_i}{A \sum_j q_j}, \qquad
          R_d^{total} = \rho_{ref}\frac{\sum_i p_i}{\sum_j q_j},

after subtracting the dark frame from both. The beam's centre and width come from the
reference image, which is the beam itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize

__all__ = [
    "Calibrated",
    "RadialProfile",
    "beam_center",
    "beam_sigma",
    "beam_window_mm",
    "calibrate",
    "channel_sums",
    "check_image",
    "half_max_radius_px",
    "merge_brackets",
    "radial_profile",
]


def check_image(image, *, name: str = "image") -> np.ndarray:
    """``image`` as float64 ``(H, W, C)``; raises naming ``name`` if not 2-D/3-D or not finite."""
    image = np.asarray(image, dtype=np.float64)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3:
        raise ValueError(f"`{name}` must have shape (H, W[, C]); got {image.shape}.")
    bad = int(image.size - np.count_nonzero(np.isfinite(image)))
    if bad:
        raise ValueError(f"`{name}` has {bad} non-finite pixel values; mask them first.")
    return image


def channel_sums(image) -> np.ndarray:
    """Sum of an ``(H, W, C)`` image over its pixels, ``(C,)``: a dot product with ones (a
    strided sum over the two pixel axes is 8 times slower at 512^2 x 3)."""
    flat = np.asarray(image).reshape(-1, np.shape(image)[-1])
    return np.ones(flat.shape[0], flat.dtype) @ flat


@dataclass(frozen=True)
class Calibrated:
    """Reflectance image [1/mm^2] ``(H, W, C)`` and the total diffuse reflectance ``(C,)``
    within the field of view (its error comes from :func:`measure.pipeline.fit_measurement`'s
    noise model, which sees the whole image)."""

    reflectance: np.ndarray
    total_reflectance: np.ndarray


def calibrate(measurement, reference, pixel_mm: float, *, reference_reflectance: float = 0.99,
              dark=None) -> Calibrated:
    """Calibrate a measurement by the white reference (module docstring)."""
    meas = check_image(measurement, name="measurement")
    ref = check_image(reference, name="reference")
    if meas.shape != ref.shape:
        raise ValueError(f"`measurement` {meas.shape} and `reference` {ref.shape} differ in shape.")
    if dark is not None:
        dark = check_image(dark, name="dark")
        if dark.shape != meas.shape:
            raise ValueError(f"`dark` {dark.shape} does not match `measurement` {meas.shape}.")
        meas, ref = meas - dark, ref - dark
    if not (0 < reference_reflectance <= 1):
        raise ValueError(f"reference_reflectance must be in (0, 1]; got {reference_reflectance:g}.")
    if not (np.isfinite(pixel_mm) and pixel_mm > 0):
        raise ValueError(f"pixel_mm must be finite and > 0 [mm]; got {pixel_mm:g}.")
    ref_sum = channel_sums(ref)
    if np.any(ref_sum <= 0):
        raise ValueError("`reference` holds no light after dark subtraction (its sum is <= 0 in some channel).")
    area = pixel_mm**2
    reflectance = reference_reflectance * meas / (area * ref_sum)
    total = reference_reflectance * channel_sums(meas) / ref_sum
    return Calibrated(reflectance, total)


def beam_center(image, *, iterations: int = 5) -> tuple[float, float]:
    """Sub-pixel (row, col) of the beam: the intensity-weighted centroid within a window.

    Starts at the brightest pixel; each iteration takes the centroid of the (non-negative)
    channel sum within five half-maximum radii of the current estimate. For a sampled
    symmetric beam the windowed centroid is unbiased, unlike a thresholded one.
    """
    image = check_image(image).sum(axis=-1)
    peak = image.max()
    if peak <= 0:
        raise ValueError("beam_center: the image holds no light.")
    window = max(5 * half_max_radius_px(image), 3.0)
    center = np.unravel_index(np.argmax(image), image.shape)
    for _ in range(iterations):
        box, rows, cols = _window_box(image, center, window)
        weights = np.clip(box, 0, None) * ((rows - center[0]) ** 2 + (cols - center[1]) ** 2 <= window**2)
        total = weights.sum()
        center = (float((rows * weights).sum() / total), float((cols * weights).sum() / total))
    return center


def _window_box(image, center, radius):
    """The part of a 2-D ``image`` that holds the disc of ``radius`` [px] around ``center``, and
    its row and column indices (broadcastable): the beam's moments need only that box."""
    r0, c0 = (max(int(np.floor(x - radius)), 0) for x in center)
    r1, c1 = (min(int(np.ceil(x + radius)) + 1, n) for x, n in zip(center, image.shape))
    return image[r0:r1, c0:c1], np.arange(r0, r1)[:, None], np.arange(c0, c1)[None, :]


def half_max_radius_px(image) -> float:
    """Radius [px] of a disc with the area of the pixels above half the peak of ``image``
    (2-D, or ``(H, W, C)`` summed over channels): a beam's rough width."""
    image = np.asarray(image, dtype=float)
    total = image.sum(axis=-1) if image.ndim == 3 else image
    return float(np.sqrt(max(np.count_nonzero(total > 0.5 * total.max()), 1) / np.pi))


def beam_window_mm(reference, pixel_mm: float) -> float:
    """The window [mm] of :func:`beam_sigma`: 10x the radius at half maximum, at least 5 pixels."""
    return max(10 * half_max_radius_px(check_image(reference, name="reference")) * pixel_mm, 5 * pixel_mm)


def beam_sigma(reference, center, pixel_mm: float, *, radius_mm: float | None = None) -> float:
    r"""Standard deviation [mm] of the beam from the reference's second moment, :math:`\langle r^2\rangle = 2\sigma^2`.

    Only pixels within ``radius_mm`` (default: 10x the rough width, at least 5 pixels)
    count, so noise far away does not inflate the moment.
    """
    image = check_image(reference, name="reference").sum(axis=-1)
    if radius_mm is None:
        radius_mm = beam_window_mm(reference, pixel_mm)
    box, rows, cols = _window_box(image, center, radius_mm / pixel_mm)
    r2 = ((rows - center[0]) ** 2 + (cols - center[1]) ** 2) * pixel_mm**2
    weights = np.clip(box, 0, None) * (r2 <= radius_mm**2)
    return float(np.sqrt((weights * r2).sum() / (2 * weights.sum())))


@dataclass(frozen=True)
class RadialProfile:
    """Annular means of an image around a centre.

    ``r_mm`` (B,) is the mean pixel radius in each bin, ``mean``/``stderr`` (B, C) the mean
    value and its standard error (the scatter about a straight line in r within the bin,
    over sqrt(n): the profile's own slope across an annulus is not noise), ``count`` (B,)
    the pixels per bin;
    ``pixel_r_mm`` and ``bin_index`` list every pixel used, for models that average
    over the same pixels. ``noise_model`` (C, 2), where the noise was pooled, holds each
    channel's per-pixel variance ``read + shot * signal``; :meth:`stderr_for` evaluates it at a
    model's signal.
    """

    r_mm: np.ndarray
    mean: np.ndarray
    stderr: np.ndarray
    count: np.ndarray
    pixel_r_mm: np.ndarray
    bin_index: np.ndarray
    noise_model: np.ndarray | None = None

    def stderr_for(self, signal) -> np.ndarray:
        """Standard error of each bin's mean were its expected value ``signal`` ``(B, C)``.

        The pooled noise model evaluated at the expected signal rather than at the measured mean
        (Pearson's chi-square rather than Neyman's). A bin whose mean fell far below its
        expectation by chance (a Monte Carlo image's far bins, hit by a few deep photons) would
        otherwise be given a variance that small too, and its weight would steer the whole fit:
        on a skin walk image at 40 degrees one such bin, mean 7e-26 against an expected 1e-9 and
        an error of 5e-16, held z = -2e6 at the truth, and the fit doubled both coefficients.
        Where no noise model was pooled, or its variance is not positive, :attr:`stderr`.
        """
        signal = np.asarray(signal, dtype=float)
        if self.noise_model is None:
            return self.stderr
        read, shot = self.noise_model[:, 0], self.noise_model[:, 1]
        variance = read + shot * np.clip(signal, 0, None)
        pooled = variance > 0
        return np.where(pooled, np.sqrt(np.where(pooled, variance, 0.0) / self.count[:, None]), self.stderr)


def _pooled_variance(variance, mean, counts):
    """Per-pixel variance as read + shot noise, ``a + b * mean``, fitted over all bins: the
    pooled variance per bin ``(B, C)`` and the coefficients ``(a, b)`` per channel ``(C, 2)``.

    A bin's own scatter rests on few pixels near the centre (a chi-square of 2 degrees of
    freedom for 4 pixels can be ten times too small); a linear camera's noise follows
    ``a + b * signal``, so one fit per channel over all bins (weighted by their degrees of
    freedom) gives every bin a stable variance.
    """
    dof = np.maximum(counts - 2, 0).astype(float)
    pooled = np.empty_like(variance)
    coefficients = np.zeros((variance.shape[1], 2))
    for c in range(variance.shape[1]):
        x, y = np.clip(mean[:, c], 0, None), variance[:, c]
        design = np.stack([np.ones_like(x), x], -1)
        # Bins where the profile curves sharply across the annulus (the peak of a transport
        # radiance profile at the beam) keep a scatter far above noise even after the straight
        # line is removed, and one such bright bin has the leverage to set the slope b for all
        # (seen: noise overstated 7x). So start robustly (the read term from the faintest
        # quarter of the bins, the slope from the median ratio of the rest of the scatter to
        # signal), then refit without bins whose scatter exceeds 4x the model. A start without
        # the read term had called every read-noise-dominated bin an outlier, so the refit never
        # saw them, and far bins of a dark channel got a thirtieth of their variance (ketchup
        # green, seed 4: chi2/dof 5.2).
        has_dof = dof > 0
        faint = has_dof & (x <= np.quantile(x[has_dof], 0.25)) if has_dof.any() else has_dof
        read = np.median(y[faint]) if faint.any() else 0.0
        positive = has_dof & (x > 0)
        slope = np.median(np.maximum(y[positive] - read, 0) / x[positive]) if positive.any() else 0.0
        model = read + slope * x
        use = has_dof & ((y <= 4 * model) | (model <= 0))
        for _ in range(3):
            weights = np.sqrt(dof * use)[:, None]
            # Non-negative least squares, not lstsq clipped afterwards (a clipped negative
            # read term would leave the slope fitted for it).
            (a, b), _ = scipy.optimize.nnls(design * weights, y * weights[:, 0])
            model = a + b * x
            use = has_dof & ((y <= 4 * model) | (model <= 0))
        pooled[:, c] = np.where(model > 0, model, y)
        coefficients[c] = a, b
    return pooled, coefficients


def radial_profile(image, center, pixel_mm: float, *, n_bins: int = 64, r_min_mm: float | None = None,
                   r_max_mm: float | None = None, min_count: int = 4, pooled_noise: bool = True) -> RadialProfile:
    """Bin pixels into log-spaced annuli around ``center`` (row, col).

    Bins run from ``r_min_mm`` (default one pixel) to ``r_max_mm`` (default the largest
    circle inside the image); pixels inside ``r_min_mm`` form the first bin. Bins with
    fewer than ``min_count`` pixels are dropped. With ``pooled_noise`` (default) the
    per-pixel variance is the read + shot noise model fitted over all bins
    (``_pooled_variance``) rather than each bin's own scatter.
    """
    image = check_image(image)
    h, w, n_channels = image.shape
    r = np.hypot(np.arange(h)[:, None] - center[0], np.arange(w)[None, :] - center[1]).reshape(-1) * pixel_mm
    values = image.reshape(-1, n_channels)
    r_max_mm = r_max_mm or min(center[0], center[1], h - 1 - center[0], w - 1 - center[1]) * pixel_mm
    r_min_mm = r_min_mm or pixel_mm
    if not (0 < r_min_mm < r_max_mm):
        raise ValueError(f"radial_profile needs 0 < r_min_mm < r_max_mm; got {r_min_mm}, {r_max_mm}.")
    edges = np.concatenate([[0.0], np.geomspace(r_min_mm, r_max_mm, n_bins)])
    inside = r <= r_max_mm
    if not inside.all():  # masks copy: skip them where they keep everything
        r, values = r[inside], values[inside]
    index = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, n_bins - 1)
    counts = np.bincount(index, minlength=n_bins)
    keep = counts >= min_count
    used = keep[index]
    counts = counts[keep]
    # Pixels of dropped bins go to one extra bin that is cut off the sums, rather than being
    # removed from (pixels, C) copies of the image.
    index = np.where(used, (np.cumsum(keep) - 1)[index], counts.size)

    def per_bin(weights):
        return np.bincount(index, weights, minlength=counts.size + 1)[:-1]

    r_mean = per_bin(r) / counts
    dr = r - np.append(r_mean, 0.0)[index]
    sxx = per_bin(dr**2)
    channels = np.ascontiguousarray(values.T)  # one copy: bincount wants contiguous weights
    mean = np.stack([per_bin(v) for v in channels], -1) / counts[:, None]
    # The spread inside an annulus is mostly the profile's own slope across it, not noise:
    # remove a straight line in r per bin and take the scatter about it. Its sum of squares
    # from the bin's sums, sum v^2 - n m^2 - b^2 sum dr^2 (dr is centred in each bin), not
    # from per-pixel residuals: no (pixels, C) gathers. The cancellation costs eps * (signal /
    # noise)^2 of the variance: 1e-10 at a per-pixel signal-to-noise of 1000.
    slope = np.stack([per_bin(dr * v) for v in channels], -1) / np.maximum(sxx, 1e-300)[:, None]
    squares = np.stack([per_bin(v * v) for v in channels], -1)
    sq = np.maximum(squares - counts[:, None] * mean**2 - slope**2 * sxx[:, None], 0.0)
    variance = sq / np.maximum(counts[:, None] - 2, 1)
    noise_model = None
    if pooled_noise:
        variance, noise_model = _pooled_variance(variance, mean, counts)
    std = np.sqrt(variance)
    if not used.all():
        r, index = r[used], index[used]
    return RadialProfile(r_mean, mean, std / np.sqrt(counts[:, None]), counts, r, index, noise_model)


def merge_brackets(frames, exposure_times, *, saturation: float, dark=None, black_level: float = 0.0,
                   names=None) -> np.ndarray:
    """Merge exposure brackets of a linear camera into one HDR image (Debevec & Malik style).

    Each frame's value is ``(frame - dark) / t``; frames are averaged with a hat weight of
    the raw value (0 at ``black_level`` and ``saturation``, 1 in the middle) times the
    exposure time (longer exposures collect more light, so less relative shot noise).
    Saturated pixels (>= 0.99 ``saturation``) get weight 0.

    Raises
    ------
    ValueError
        No frames, mismatched shapes or times, or pixels saturated in every frame (the
        message names the shortest frame).
    """
    frames = [check_image(f, name=(names[i] if names else f"frame {i}")) for i, f in enumerate(frames)]
    times = np.asarray(exposure_times, dtype=float)
    if not frames:
        raise ValueError("merge_brackets needs at least one frame.")
    if times.shape != (len(frames),) or np.any(times <= 0):
        raise ValueError(f"merge_brackets needs one positive exposure time per frame; got {exposure_times!r}.")
    if any(f.shape != frames[0].shape for f in frames):
        raise ValueError(f"merge_brackets: frames differ in shape {[f.shape for f in frames]}.")
    dark = np.zeros_like(frames[0]) if dark is None else check_image(dark, name="dark")
    numerator = np.zeros_like(frames[0])
    denominator = np.zeros_like(frames[0])
    span = saturation - black_level
    for frame, t in zip(frames, times):
        z = (frame - black_level) / span
        hat = np.clip(1 - np.abs(2 * z - 1), 0, None)
        hat = np.where(frame >= black_level + 0.99 * span, 0.0, np.maximum(hat, 1e-3))
        weight = hat * t
        numerator += weight * (frame - dark) / t
        denominator += weight
    saturated = denominator == 0
    if np.any(saturated):
        shortest = int(np.argmin(times))
        label = names[shortest] if names else f"frame {shortest} (t={times[shortest]})"
        raise ValueError(f"{int(saturated.sum())} pixel values are saturated in every bracket, even {label}; "
                         "add a shorter exposure.")
    return numerator / denominator
