r"""The pixel size on the sample, measured from a checkerboard of known square size in the frame.

A beam-profile fit cannot see scale: an image read with pixels ten times too large fits exactly
as well, with every coefficient ten times too small (:mod:`measure.checks`). The pixel size
must come from the scene: photograph a printed checkerboard lying where the sample lies, with
the same camera and lens setting, and divide its square size by the squares' size in pixels.

The squares' size in pixels comes from the image's spectrum. A checkerboard of square size
:math:`s` pixels, at any rotation, is the product of two square waves of period :math:`2s`
along its axes; its strongest Fourier components lie at the four frequencies
:math:`(\pm 1/2s, \pm 1/2s)` in the board's axes, a distance :math:`|f| = \sqrt{2}/(2s)`
cycles per pixel from the origin. So :math:`s = \sqrt{2}/(2|f|)` wherever the board is turned.
The peak is found on a zero-padded spectrum of the windowed image (Hann window: the board's
edge and the rest of the frame leak little) and refined by a parabola through the log-magnitudes
around it, to a fraction of a bin. A board of 8 or more squares across the frame measures the
pixel size to about 0.1 % (``tests/measure/test_target.py``: rotated, blurred, noisy boards).
"""

from __future__ import annotations

import numpy as np

__all__ = ["checker_square_px", "pixel_mm_from_checkerboard"]

PADDING = 4  # the spectrum is sampled 4x finer than the image's own bins


def checker_square_px(image) -> float:
    """The size of a checkerboard's squares in pixels (module docstring).

    Parameters
    ----------
    image : array_like ``(H, W)`` or ``(H, W, C)``
        A photo of the board (linear or not: only the pattern's period matters); channels are
        averaged. The board should fill most of the frame, with at least 4 squares across.

    Raises
    ------
    ValueError
        An image smaller than 16 x 16, not finite, or without a periodic pattern (the peak is
        at the window's own width, or no stronger than the spectrum's background).
    """
    pixels = np.asarray(image, dtype=float)
    if pixels.ndim == 3:
        pixels = pixels.mean(axis=-1)
    if pixels.ndim != 2 or min(pixels.shape) < 16:
        raise ValueError(f"a checkerboard image must be at least 16 x 16 pixels; got shape {np.shape(image)}")
    if not np.all(np.isfinite(pixels)):
        raise ValueError("the checkerboard image has NaN or infinite pixels")
    height, width = pixels.shape
    window = np.outer(np.hanning(height), np.hanning(width))
    centred = (pixels - np.average(pixels, weights=window)) * window
    size = (PADDING * height, PADDING * width)
    magnitude = np.abs(np.fft.fftshift(np.fft.fft2(centred, s=size)))
    fy = np.fft.fftshift(np.fft.fftfreq(size[0]))
    fx = np.fft.fftshift(np.fft.fftfreq(size[1]))
    radius = np.hypot(fy[:, None], fx[None, :])
    # Below 4 cycles across the frame is the window's own blur of the mean, not a pattern.
    low = 4.0 / min(height, width)
    magnitude = np.where(radius > low, magnitude, 0.0)
    row, col = np.unravel_index(np.argmax(magnitude), magnitude.shape)
    peak = magnitude[row, col]
    if not peak > 20 * np.median(magnitude[radius > low]):
        raise ValueError("no checkerboard found: the image's spectrum has no peak well above its background; is the "
                         "board in focus and filling most of the frame?")

    def refined(values, index):  # a parabola through the log-magnitudes of the peak and its neighbours
        if index == 0 or index == values.size - 1:
            return 0.0
        left, centre, right = np.log(np.maximum(values[index - 1:index + 2], 1e-300))
        curvature = left - 2 * centre + right
        return 0.0 if curvature >= 0 else 0.5 * (left - right) / curvature

    step_y, step_x = fy[1] - fy[0], fx[1] - fx[0]
    peak_fy = fy[row] + refined(magnitude[:, col], row) * step_y
    peak_fx = fx[col] + refined(magnitude[row, :], col) * step_x
    return float(np.sqrt(2) / (2 * np.hypot(peak_fy, peak_fx)))


def pixel_mm_from_checkerboard(image, square_mm: float) -> float:
    """Pixel size on the sample [mm]: ``square_mm`` over :func:`checker_square_px` of ``image``.

    Raises
    ------
    ValueError
        ``square_mm`` not a positive finite number, or no board found (:func:`checker_square_px`).
    """
    square_mm = float(square_mm)
    if not (np.isfinite(square_mm) and square_mm > 0):
        raise ValueError(f"the square size must be > 0 mm (the printed board's square edge); got {square_mm:g}")
    return square_mm / checker_square_px(image)
