"""Camera photos in: raw files (rawpy), 16-bit TIFF/PNG and OpenEXR, read linearly.

Every reader returns an :class:`~measure.exr.ExrImage`: float64 pixels ``(H, W, 3)`` (or the
EXR's channels), normalised so that the sensor's clip level is 1.0 for raw and integer files,
and a header with what the fit needs from the file:

``jsss_exposure``
    exposure time [s] x ISO / 100 (the relative sensitivity of the frame), so that exposure
    brackets merge straight from the files; only where the file records an exposure time
    (ISO 100 assumed where it records none).
``jsss_saturation``
    the clip level in the same units as the pixels (1.0). Pixels at or above it are clipped
    and are excluded when brackets merge; a single frame with clipped pixels is refused.
``jsss_white_balance``
    what was applied to a raw file: ``"none"`` (default: unit multipliers; the white
    reference calibrates each channel, so no balance is needed), ``"camera"`` (as shot) or
    ``"daylight"``.

Raw files are demosaicked bilinearly (a linear operation) in the camera's own RGB (no colour
matrix: a matrix mixes channels, and each channel's fit needs that channel's light), with
no gamma and no auto-brightness; LibRaw subtracts the black level. Sensor pixels at the white
level mark their 3 x 3 neighbourhood of output pixels as clipped (the demosaic spreads them).
TIFF and PNG files must hold linear data: a file that declares sRGB (an ICC profile or EXIF
colour space, PNG's sRGB or gAMA chunk) gives a :class:`NonLinearWarning`; 8-bit files are
refused (too few levels for an HDR measurement).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from jsss.render.surface_maps import checked_png_header, read_png_16_bit_colour
from measure.exr import ExrError, ExrImage, read_exr

__all__ = ["NonLinearWarning", "PhotoError", "RAW_SUFFIXES", "read_image"]

RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".raf", ".orf", ".rw2", ".pef", ".srw")
_TIFF = (".tif", ".tiff")
WHITE_BALANCES = ("none", "camera", "daylight")


class PhotoError(ExrError):
    """An image file could not be read as a linear measurement; the message names the file."""


class NonLinearWarning(UserWarning):
    """The file says its values are gamma-encoded (sRGB), not linear in light."""


def read_image(path, channels=None, *, white_balance: str = "none") -> ExrImage:
    """Read a measurement frame from a raw, TIFF, PNG or EXR file (chosen by the suffix).

    Parameters
    ----------
    path : str or Path
    channels : sequence of str, optional
        EXR channel names; other formats are always ``("R", "G", "B")``.
    white_balance : {"none", "camera", "daylight"}, keyword-only
        Multipliers applied to a raw file (ignored for the other formats).

    Raises
    ------
    PhotoError
        Missing, unsupported or corrupt file, 8-bit data, non-finite values.
    """
    path = Path(path)
    if white_balance not in WHITE_BALANCES:
        raise ValueError(f"white_balance must be one of {WHITE_BALANCES}; got {white_balance!r}.")
    suffix = path.suffix.lower()
    if suffix == ".exr":
        return read_exr(path, channels)
    if not path.is_file():
        raise PhotoError(f"{path}: no such file")
    if suffix in RAW_SUFFIXES:
        image = _read_raw(path, white_balance)
    elif suffix in _TIFF:
        image = _read_tiff(path)
    elif suffix == ".png":
        image = _read_png(path)
    else:
        raise PhotoError(f"{path}: unsupported image type {suffix or '(no suffix)'}; use OpenEXR (.exr), a raw file "
                         f"({', '.join(RAW_SUFFIXES)}), or a 16-bit linear TIFF or PNG")
    if channels is not None and tuple(channels) != image.channels:
        raise PhotoError(f"{path}: holds channels {image.channels}; cannot give {tuple(channels)}")
    return image


def _why(error) -> str:
    """The first line of a library's error (some wrap several lines of advice)."""
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__


def _exposure(seconds, iso):
    """exposure time x ISO / 100, or None where the time is unknown."""
    if not seconds or not np.isfinite(seconds) or seconds <= 0:
        return None
    return float(seconds) * (float(iso) / 100.0 if iso and iso > 0 else 1.0)


def _header(exposure, extra=None):
    header = {"jsss_saturation": 1.0, **(extra or {})}
    if exposure is not None:
        header["jsss_exposure"] = exposure
    return header


def _from_integers(path, data, bits):
    """Integer samples (H, W[, C]) scaled to [0, 1] by the largest code of ``bits``."""
    data = np.asarray(data)
    if data.dtype.kind not in "ui":
        if data.dtype.kind == "f":
            pixels = data.astype(np.float64)
            if not np.all(np.isfinite(pixels)):
                raise PhotoError(f"{path}: NaN/Inf pixel value(s); fix or mask the image first")
            return pixels
        raise PhotoError(f"{path}: unsupported sample type {data.dtype}")
    if bits <= 8:
        raise PhotoError(f"{path}: 8-bit image: 256 levels cannot hold a beam profile's range; save 16-bit linear "
                         "TIFF/PNG, raw or EXR")
    return data.astype(np.float64) / float(2 ** bits - 1)


def _as_rgb(path, pixels):
    if pixels.ndim == 2:
        pixels = np.repeat(pixels[..., None], 3, axis=-1)
    if pixels.ndim != 3 or pixels.shape[-1] not in (3, 4):
        raise PhotoError(f"{path}: expected an RGB image; got shape {pixels.shape}")
    return pixels[..., :3]


def _read_tiff(path) -> ExrImage:
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            data = page.asarray()
            tags = {tag.code: tag.value for tag in page.tags.values()}
            exif = tags.get(34665) if isinstance(tags.get(34665), dict) else {}
    except Exception as error:  # tifffile raises its own TiffFileError, ValueError, struct errors
        raise PhotoError(f"{path}: not a readable TIFF file ({_why(error)})") from None
    icc = tags.get(34675, b"") or b""
    colour_space = exif.get("ColorSpace", tags.get(40961))
    if b"sRGB" in bytes(icc) or colour_space == 1:
        warnings.warn(f"{path}: the file says sRGB (gamma-encoded), not linear; the fit assumes pixels "
                      "proportional to light", NonLinearWarning, stacklevel=3)
    seconds = exif.get("ExposureTime", tags.get(33434))
    if isinstance(seconds, tuple):
        seconds = seconds[0] / seconds[1] if seconds[1] else None
    iso = exif.get("ISOSpeedRatings", tags.get(34855))
    if isinstance(iso, tuple):
        iso = iso[0]
    bits = int(np.atleast_1d(tags.get(258, data.dtype.itemsize * 8))[0])
    pixels = _as_rgb(path, _from_integers(path, data, bits))
    return ExrImage(pixels, ("R", "G", "B"), _header(_exposure(seconds, iso)), path)


def _png_header(path) -> tuple[int, int]:
    """:func:`~jsss.render.surface_maps.checked_png_header`, its refusal as a PhotoError."""
    try:
        return checked_png_header(path)
    except ValueError as error:
        raise PhotoError(str(error)) from None


def _read_png(path) -> ExrImage:
    import imageio.v3 as iio

    depth, colour = _png_header(path)
    try:
        meta = iio.immeta(path, plugin="pillow")
        if depth == 16 and colour in (2, 6):
            data = read_png_16_bit_colour(path)
        else:
            data = iio.imread(path, plugin="pillow")
    except Exception as error:  # imageio wraps Pillow's errors in several types, pypng raises its own
        raise PhotoError(f"{path}: not a readable PNG file ({_why(error)})") from None
    if "srgb" in meta or "icc_profile" in meta or abs(float(meta.get("gamma", 1.0)) - 1.0) > 1e-3:
        warnings.warn(f"{path}: the file says sRGB or a display gamma, not linear; the fit assumes pixels "
                      "proportional to light", NonLinearWarning, stacklevel=3)
    bits = 16 if np.asarray(data).dtype == np.uint16 else 8
    pixels = _as_rgb(path, _from_integers(path, data, bits))
    return ExrImage(pixels, ("R", "G", "B"), _header(None), path)


def _read_raw(path, white_balance) -> ExrImage:
    import rawpy

    try:
        with rawpy.imread(str(path)) as raw:
            options = dict(gamma=(1, 1), no_auto_bright=True, output_bps=16, output_color=rawpy.ColorSpace.raw,
                           demosaic_algorithm=rawpy.DemosaicAlgorithm.LINEAR, user_flip=0, use_auto_wb=False)
            if white_balance == "camera":
                options["use_camera_wb"] = True
            elif white_balance == "daylight":
                options["user_wb"] = list(raw.daylight_whitebalance)
            else:
                options["user_wb"] = [1.0, 1.0, 1.0, 1.0]
            rgb = raw.postprocess(**options)
            clipped = raw.raw_image_visible >= raw.white_level
            seconds, iso = raw.other.shutter_speed, raw.other.iso_speed
            white_level = int(raw.white_level)
    except (rawpy.LibRawError, OSError, ValueError) as error:
        raise PhotoError(f"{path}: not a readable raw file ({_why(error)})") from None
    pixels = rgb.astype(np.float64) / 65535.0
    if clipped.shape == pixels.shape[:2] and clipped.any():
        from scipy.ndimage import binary_dilation

        # The bilinear demosaic spreads a clipped sensor pixel to its 3 x 3 neighbours (not across the border).
        pixels[binary_dilation(clipped, structure=np.ones((3, 3), bool))] = 1.0
    header = _header(_exposure(seconds, iso), {"jsss_white_balance": white_balance, "jsss_white_level": white_level})
    return ExrImage(pixels, ("R", "G", "B"), header, path)
